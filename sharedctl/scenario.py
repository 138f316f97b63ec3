"""Scenario files (TOML) → a ready-to-run closed loop. Pure: takes the parsed mapping.

Keys (all SI; see README.md, "SCENARIO.toml"):
  name, duration (s), dt (s)
  [robot]    kind = "omni3" | "arm2", parameter overrides
             (omni3: mass, body_inertia, wheel_inertia, wheel_radius, wheel_distance, delta)
  [[region]] K = [[...], ...], T = [...]    — the feasible set is their union
  [initial]  q, qdot
  [desired]  kind = "line" (start, velocity) | "point" (at) | "circle" (center, radius, omega)
  [human]    kind = "scripted" | "spring" | "adversarial" (pushes at the desired start with
             `deflection` of the handle, default 1), kp, kd
  [sharing]  mode = "shared" | "machine" | "human", b1, b2, b0, blend_time_constant, min_machine_dwell,
             hold_pushed_faces
  [reference] epsilon, gamma
  [gains.ce] Kp, lam, gamma_theta   [gains.nce] (over [gains.ce]) Kp, lam, gamma_theta, k_q, alpha_n, gamma_n, nu
  [gains.of] K1, k2, gamma_theta, sign_width   [gains.of_barrier] Kp, lam, gamma_theta, barrier_weight
  [gains.observer] Ka, Kb, sign_width
  [gains.adaptation] (every law's robust θ̂ update, docs/control.md §11) leakage (σ₀, 1/s; 0: off),
             band_lower, band_upper (the trust box T), theta_lower, theta_upper (the physical box B);
             unset: the model's
  theta_hat0 = [...]  (default zeros, as in the paper)
  [backup]   enabled, hold (s), margin; omni3: brake_torque, friction_coulomb, friction_viscous (on by
             default); arm2: brake_torque = [c1, c2] (N·m per joint; off unless enabled = true)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from .backup import arm_backup, omni_backup
from .constraints import FeasibleSet, Polytope
from .human import AdversarialOperator, CircleTrajectory, JoystickSpring, LineTrajectory, ScriptedOperator
from .models import OmniRobot, PlanarArm
from .models.omni_robot import OmniRobotParameters
from .models.planar_arm import PlanarArmParameters
from .reference import ReferenceShape
from .sets import Bands
from .sharing import Mode, SharingParameters
from .simulator import ClosedLoop, make_controller


class ScenarioError(ValueError):
    """A scenario file with a missing or bad key; the message names the key."""


@dataclass
class Scenario:
    name: str
    duration: float
    dt: float
    data: dict = field(repr=False)

    def closed_loop(self, controller: str | None = None) -> tuple[ClosedLoop, np.ndarray, np.ndarray]:
        """Build (loop, q0, q̇0); `controller` overrides the file's `controller` key."""
        return build(self.data, controller)


def _vector(data, key, n=None, where=""):
    try:
        arr = np.asarray(data[key], dtype=float).reshape(-1)
    except KeyError:
        raise ScenarioError(f"missing key {where}{key}") from None
    except (TypeError, ValueError):
        raise ScenarioError(f"{where}{key} must be a list of numbers") from None
    if n is not None and arr.size != n:
        raise ScenarioError(f"{where}{key} must have {n} entries, has {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ScenarioError(f"{where}{key} must be finite")
    return arr


def _number(data, key, default=None, where="", positive=False):
    if key not in data:
        if default is None:
            raise ScenarioError(f"missing key {where}{key}")
        return default
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioError(f"{where}{key} must be a finite number")
    if positive and value <= 0:
        raise ScenarioError(f"{where}{key} must be positive")
    return float(value)


def _overrides(cls, table, where):
    names = {f.name for f in fields(cls)}
    unknown = set(table) - names - {"kind"}
    if unknown:
        raise ScenarioError(f"unknown key {where}{sorted(unknown)[0]} (allowed: {sorted(names)})")
    return cls(**{k: _number(table, k, where=where) for k in table if k != "kind"})


def parse(data: dict) -> Scenario:
    """Validate the top level once, with errors naming the bad key."""
    name = data.get("name", "scenario")
    duration = _number(data, "duration", positive=True)
    dt = _number(data, "dt", 1e-3, positive=True)
    if dt > duration:
        raise ScenarioError("dt must not exceed duration")
    build(data, None)  # full validation up front
    return Scenario(str(name), duration, dt, data)


def build(data: dict, controller: str | None):
    robot = data.get("robot", {})
    kind = robot.get("kind", "omni3")
    if kind == "omni3":
        model = OmniRobot(_overrides(OmniRobotParameters, robot, "robot."))
    elif kind == "arm2":
        model = PlanarArm(_overrides(PlanarArmParameters, robot, "robot."))
    else:
        raise ScenarioError(f"robot.kind must be omni3 or arm2, got {kind!r}")
    n = model.n

    regions = data.get("region")
    if not regions:
        raise ScenarioError("missing key region (at least one [[region]] with K and T)")
    polys = []
    for i, reg in enumerate(regions):
        where = f"region[{i}]."
        try:
            K = np.asarray(reg["K"], dtype=float)
        except KeyError:
            raise ScenarioError(f"missing key {where}K") from None
        if K.ndim != 2 or K.shape[1] != n:
            raise ScenarioError(f"{where}K must be a list of rows of {n} numbers")
        T = _vector(reg, "T", K.shape[0], where)
        try:
            polys.append(Polytope.from_rows(K, T))
        except ValueError as exc:
            raise ScenarioError(f"{where}: {exc}") from None
    feasible = FeasibleSet.from_regions(polys, completion_distance=_number(data, "completion_distance", 1e3))

    initial = data.get("initial", {})
    q0 = _vector(initial, "q", n, "initial.")
    v0 = _vector(initial, "qdot", n, "initial.") if "qdot" in initial else np.zeros(n)

    desired = data.get("desired", {})
    dk = desired.get("kind", "line")
    if dk == "line":
        start = _vector(desired, "start", n, "desired.") if "start" in desired else q0.copy()
        trajectory = LineTrajectory(start, _vector(desired, "velocity", n, "desired."))
    elif dk == "point":
        trajectory = LineTrajectory(_vector(desired, "at", n, "desired."), np.zeros(n))
    elif dk == "circle":
        trajectory = CircleTrajectory(
            n, _vector(desired, "center", 2, "desired."), _number(desired, "radius", where="desired.", positive=True),
            _number(desired, "omega", where="desired."),
        )
    else:
        raise ScenarioError(f"desired.kind must be line, point or circle, got {dk!r}")

    human = data.get("human", {})
    kp = np.broadcast_to(_vector({"kp": human.get("kp", 20.0)}, "kp", where="human."), (n,)).copy()
    kd = np.broadcast_to(_vector({"kd": human.get("kd", 12.0)}, "kd", where="human."), (n,)).copy()
    hk = human.get("kind", "scripted")
    if hk == "scripted":
        operator = ScriptedOperator(trajectory, kp, kd)
    elif hk == "spring":
        operator = JoystickSpring(trajectory, kp)
    elif hk == "adversarial":
        target = trajectory.sample(0.0).q
        operator = AdversarialOperator(trajectory, kp, target,
                                       _number(human, "deflection", 1.0, "human.", positive=True))
    else:
        raise ScenarioError(f"human.kind must be scripted, spring or adversarial, got {hk!r}")

    sharing = data.get("sharing", {})
    try:
        bands = Bands(_number(sharing, "b1", 0.3, "sharing."), _number(sharing, "b2", 0.6, "sharing."),
                      _number(sharing, "b0", 0.025, "sharing."), _number(sharing, "standoff", 0.15, "sharing."))
        mode = Mode(sharing.get("mode", "shared"))
        ref = data.get("reference", {})
        shape = ReferenceShape(_number(ref, "epsilon", 0.05, "reference."), _number(ref, "gamma", 40.0, "reference."))
    except ValueError as exc:
        raise ScenarioError(f"sharing/reference: {exc}") from None
    if bands.b0 >= shape.epsilon:
        raise ScenarioError("sharing.b0 must be smaller than reference.epsilon "
                            "(the projection must lie outside the inner band)")
    if 0.0 < bands.standoff <= shape.epsilon:
        raise ScenarioError("sharing.standoff must be larger than reference.epsilon, or 0 "
                            "(the machine's rest point, ε inside a face, must lie in the standoff band)")
    dwell = sharing.get("min_machine_dwell", 0.25)
    if isinstance(dwell, bool) or not isinstance(dwell, (int, float)) or not (0 <= dwell < 1e3):
        raise ScenarioError("sharing.min_machine_dwell must be a number of seconds >= 0")
    hold = sharing.get("hold_pushed_faces", True)
    if not isinstance(hold, bool):
        raise ScenarioError("sharing.hold_pushed_faces must be true or false")
    params = SharingParameters(bands, _number(sharing, "blend_time_constant", 0.3, "sharing.", True),
                               mode, float(dwell), hold)

    kind_ctrl = controller or data.get("controller", "ce")
    try:
        machine = make_controller(kind_ctrl, data.get("gains", {}), model)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"gains/controller: {exc}") from None
    theta0 = _vector(data, "theta_hat0", model.n_theta) if "theta_hat0" in data else np.zeros(model.n_theta)
    loop = ClosedLoop(model, feasible, operator, machine, params, shape, theta0, _backup(data.get("backup", {}), model))
    if not feasible.contains(q0):
        raise ScenarioError("initial.q is outside the feasible set")
    return loop, q0, v0


#: `[backup]` keys and defaults: what the controller assumes of the fail-safe stop (lower bounds of the
#: robot's brakes and friction, the drives' watchdog); the simulated robot's own values are `[robot_sim]`'s
BACKUP_DEFAULTS = {"hold": 0.1, "brake_torque": 1.0, "friction_coulomb": 0.05, "friction_viscous": 0.01,
                   "margin": 0.01}

#: `[backup]` keys and defaults for robot.kind = arm2: the drives' watchdog (s; a small arm's drives are
#: sampled at 1–2 kHz, and over much longer holds its motion under a held torque has no useful bound),
#: each joint's spring-applied brake (N·m; above the joint's largest gravity torque, θ4 + θ5 = 7.95 and
#: θ5 = 1.57 N·m for the default arm, so the brakes hold it at rest anywhere: a_c = 6.61 rad/s²) and δ (rad)
ARM_BACKUP_DEFAULTS = {"hold": 0.02, "brake_torque": (20.0, 5.0), "margin": 0.01}


def _backup(table, model):
    """The scenario's BackupModel (sharedctl/backup.py): on by default for the omnidirectional robot,
    `enabled = false` turns it off; for the arm off by default, `enabled = true` turns on its joint
    brakes' model (`arm_backup`)."""
    if not isinstance(table, dict):
        raise ScenarioError("backup must be a table")
    arm = isinstance(model, PlanarArm)
    defaults = ARM_BACKUP_DEFAULTS if arm else BACKUP_DEFAULTS
    unknown = set(table) - set(defaults) - {"enabled"}
    if unknown:
        allowed = sorted(defaults) + ["enabled"]
        raise ScenarioError(f"unknown key backup.{sorted(unknown)[0]} (allowed for {'arm2' if arm else 'omni3'}: "
                            f"{allowed})")
    enabled = table.get("enabled", isinstance(model, OmniRobot))
    if not isinstance(enabled, bool):
        raise ScenarioError("backup.enabled must be true or false")
    if not enabled:
        return None
    if arm:
        return _arm_backup(table, model)
    values = {}
    for key, default in BACKUP_DEFAULTS.items():
        value = _number(table, key, default, "backup.")
        if value < 0 or (key == "brake_torque" and value + _number(table, "friction_coulomb", 0.05, "backup.") <= 0):
            raise ScenarioError(f"backup.{key} must be >= 0 (and brake_torque + friction_coulomb > 0)")
        values[key] = value
    return omni_backup(model.parameters, values["brake_torque"], values["friction_coulomb"],
                       values["friction_viscous"], values["hold"], values["margin"])


def _arm_backup(table, model):
    hold = _number(table, "hold", ARM_BACKUP_DEFAULTS["hold"], "backup.")
    margin = _number(table, "margin", ARM_BACKUP_DEFAULTS["margin"], "backup.")
    if hold < 0 or margin < 0:
        raise ScenarioError("backup.hold and backup.margin must be >= 0")
    brake = (_vector(table, "brake_torque", 2, "backup.") if "brake_torque" in table
             else ARM_BACKUP_DEFAULTS["brake_torque"])
    try:
        return arm_backup(model.parameters, brake, hold, margin)
    except ValueError as exc:
        raise ScenarioError(f"backup.brake_torque: {exc}") from None
