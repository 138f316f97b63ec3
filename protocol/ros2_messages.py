"""The ROS 2 messages of `controller --ros2`: RobotState → nav_msgs/msg/Odometry and std_msgs/msg/String, CDR
bytes → geometry_msgs/msg/Twist. The conversions are pure; the CDR is rosbags' (the `ros2` extra), imported
only when a `Ros2Codec` is made.

Frames and units (REP 103, REP 105):

* **Odometry** — `header.stamp` is RobotState's `time` (wall clock, s → sec + nanosec),
  `header.frame_id` ``<robot>/odom`` (the fixed frame the controller's pose q = (x, y, ψ) is
  in), `child_frame_id` ``<robot>/base_link``. `pose.pose` is (x, y, 0) with the yaw ψ as the
  quaternion (0, 0, sin ψ/2, cos ψ/2). `twist.twist` is in the child frame, as nav_msgs
  specifies: the estimated velocity q̇̂ rotated into the body, (v_x, v_y) = R(ψ)ᵀ(ẋ, ẏ), and
  angular.z = ψ̇. Covariances are zero: not estimated.
* **Authority** — a std_msgs/msg/String whose data is RobotState's `authority`: ``human``,
  ``shared`` or ``machine`` (who drives: the operator alone, a blend, the machine alone).
* **Twist** (cmd_vel) — in the robot's base frame (REP 105): linear.x forward, linear.y left,
  angular.z counter-clockwise. Decoded into `Twist`; a payload that is not a Twist's CDR is
  `BadCdr`, a component that is not finite `NonFiniteValue`, one beyond `TWIST_BOUND`
  (100 m/s or rad/s: no robot) `OutOfRange`. What the controller makes of a Twist is its policy
  (services/controller/twist_input.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import BadCdr, NonFiniteValue, OutOfRange, WrongLength
from .messages import RobotState

ODOMETRY, TWIST, STRING = "nav_msgs/msg/Odometry", "geometry_msgs/msg/Twist", "std_msgs/msg/String"
TWIST_BOUND = 100.0           # |component| of a Twist, m/s and rad/s: beyond is no robot's
TWIST_CDR_SIZE = 4 + 6 * 8    # encapsulation header + six float64 (a Twist has no padding, no strings)
_ENCAPSULATIONS = (b"\x00\x00", b"\x00\x01")   # plain CDR, big- and little-endian (rosbags reads both)


@dataclass(frozen=True, slots=True)
class OdometryFields:
    """The values of one nav_msgs/msg/Odometry (module doc)."""

    sec: int
    nanosec: int
    frame_id: str
    child_frame_id: str
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]     # x, y, z, w
    linear: tuple[float, float, float]                  # in the child frame
    angular: tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class Twist:
    """A geometry_msgs/msg/Twist in the robot's base frame (m/s, rad/s)."""

    linear: tuple[float, float, float]
    angular: tuple[float, float, float]


def stamp(t: float) -> tuple[int, int]:
    """Seconds → (sec, nanosec) of builtin_interfaces/msg/Time, nanosec in [0, 1e9)."""
    sec = math.floor(t)
    nanosec = round((t - sec) * 1e9)
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return int(sec), int(nanosec)


def odometry_fields(state: RobotState, robot_id: str) -> OdometryFields:
    """RobotState of a planar robot (q = x, y, ψ) → the Odometry's values."""
    if len(state.q) != 3:
        raise WrongLength(f"Odometry needs a planar pose (x, y, ψ), not {len(state.q)} coordinates")
    x, y, psi = state.q
    xd, yd, psid = state.qd_hat
    c, s = math.cos(psi), math.sin(psi)
    sec, nanosec = stamp(state.time)
    return OdometryFields(sec, nanosec, f"{robot_id}/odom", f"{robot_id}/base_link", (x, y, 0.0),
                          (0.0, 0.0, math.sin(psi / 2), math.cos(psi / 2)),
                          (c * xd + s * yd, -s * xd + c * yd, 0.0), (0.0, 0.0, psid))


def check_twist(linear, angular) -> Twist:
    """Six finite components within `TWIST_BOUND`, else `NonFiniteValue` / `OutOfRange`."""
    values = (*linear, *angular)
    if not all(math.isfinite(v) for v in values):
        raise NonFiniteValue("a Twist component is not finite")
    if any(abs(v) > TWIST_BOUND for v in values):
        raise OutOfRange(f"a Twist component beyond {TWIST_BOUND:g} (m/s, rad/s)")
    return Twist(tuple(float(v) for v in linear), tuple(float(v) for v in angular))


class Ros2Codec:
    """CDR encoders and the Twist decoder on rosbags' Jazzy typestore (rosbags compiles each type's codec
    on first use: `__init__` uses each once)."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore    # the `ros2` extra

        store = get_typestore(Stores.ROS2_JAZZY)
        self.store = store
        t = store.types
        self._odometry, self._header = t[ODOMETRY], t["std_msgs/msg/Header"]
        self._time = t["builtin_interfaces/msg/Time"]
        self._pose_cov, self._pose = t["geometry_msgs/msg/PoseWithCovariance"], t["geometry_msgs/msg/Pose"]
        self._point, self._quaternion = t["geometry_msgs/msg/Point"], t["geometry_msgs/msg/Quaternion"]
        self._twist_cov, self._twist = t["geometry_msgs/msg/TwistWithCovariance"], t[TWIST]
        self._vector, self._string = t["geometry_msgs/msg/Vector3"], t[STRING]
        self._zero_covariance = np.zeros(36)
        self._zero_covariance.flags.writeable = False
        zero = (0.0, 0.0, 0.0)
        self.odometry_cdr(OdometryFields(0, 0, "odom", "base_link", zero, (0.0, 0.0, 0.0, 1.0), zero, zero))
        self.twist(self.twist_cdr(Twist(zero, zero)))
        self.string_cdr("")

    def odometry_cdr(self, f: OdometryFields) -> bytes:
        v = self._vector
        message = self._odometry(
            self._header(self._time(f.sec, f.nanosec), f.frame_id), f.child_frame_id,
            self._pose_cov(self._pose(self._point(*f.position), self._quaternion(*f.orientation)),
                           self._zero_covariance),
            self._twist_cov(self._twist(v(*f.linear), v(*f.angular)), self._zero_covariance))
        return bytes(self.store.serialize_cdr(message, ODOMETRY))

    def odometry(self, state: RobotState, robot_id: str) -> bytes:
        return self.odometry_cdr(odometry_fields(state, robot_id))

    def string_cdr(self, text: str) -> bytes:
        return bytes(self.store.serialize_cdr(self._string(text), STRING))

    def authority(self, state: RobotState) -> bytes:
        return self.string_cdr(state.authority.value)

    def twist_cdr(self, twist: Twist) -> bytes:
        v = self._vector
        return bytes(self.store.serialize_cdr(self._twist(v(*twist.linear), v(*twist.angular)), TWIST))

    def twist(self, payload: bytes) -> Twist:
        """A Twist's CDR → `Twist` (module doc for the errors)."""
        if len(payload) != TWIST_CDR_SIZE or bytes(payload[:2]) not in _ENCAPSULATIONS:
            raise BadCdr(f"a geometry_msgs/msg/Twist is {TWIST_CDR_SIZE} bytes of plain CDR")
        try:
            message = self.store.deserialize_cdr(bytes(payload), TWIST)
            linear, angular = message.linear, message.angular
            values = (linear.x, linear.y, linear.z), (angular.x, angular.y, angular.z)
        except Exception as exc:   # whatever the library raises (re-raised typed): a bad payload is BadCdr
            raise BadCdr(f"not a geometry_msgs/msg/Twist: {type(exc).__name__}") from exc
        return check_twist(*values)
