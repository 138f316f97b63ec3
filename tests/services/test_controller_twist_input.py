"""ROS 2 Twists as operator input (services/controller/twist_input.py) through the real operator policy
(operator_input.py, lease.py, replay_guard.py) on a fake clock: the Twist's CDR built byte by byte, its
attachment as rmw_zenoh's design document lays it out, the expected force and wish worked out by hand."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from sharedctl.protocol.messages import ControlRequest, OperatorCommand
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.protocol.ros2_messages import Ros2Codec
from sharedctl.services.controller.lease import OperatorLease
from sharedctl.services.controller.operator_input import OperatorInputPolicy
from sharedctl.services.controller.twist_input import TwistInput, TwistScale

KP = np.array([20.0, 20.0, 5.0])
GID = bytes(range(16))
OTHER = bytes(range(16, 32))
WALL = 1_700_000_000.0          # the senders' and the controller's wall clock at monotonic 0


@pytest.fixture(scope="module")
def codec():
    return Ros2Codec()


def make(codec, pose=(-0.9, 3.0, 0.0), mode="implicit", verify=None):
    policy = OperatorInputPolicy(KP, lease=OperatorLease(1.0, mode), verify=verify)
    policy.pose = np.array(pose)
    return policy, TwistInput(policy, codec, TwistScale(max_linear=0.5, max_angular=1.0))


def twist(vx=0.0, vy=0.0, wz=0.0, *, vz=0.0, wx=0.0, wy=0.0) -> bytes:
    return b"\x00\x01\x00\x00" + struct.pack("<6d", vx, vy, vz, wx, wy, wz)


def attachment(seq, sent, gid=GID) -> bytes:
    """seq (int64 LE), source timestamp in ns (int64 LE), GID length 16, GID."""
    return struct.pack("<qqB", seq, round((WALL + sent) * 1e9), 16) + gid


def offer(inp, payload, seq, now, gid=GID, delay=0.004):
    """A Twist sent at `now − delay` on the sender's clock, received at `now` (monotonic = wall − WALL)."""
    return inp.offer(payload, now, WALL + now, attachment(seq, now - delay, gid))


def test_the_lease_holders_forward_twist_at_yaw_half_pi_pushes_along_world_y(codec):
    """ψ = π/2: forward (body +x) is world +y. 0.25 m/s of 0.5 at full scale: deflection (0, 0.5, 0), force
    u_h = k_p ∘ d = (0, 10, 0), intent ½·20·0.5² = 2.5, wish the pose + 0.5 m ∘ d, at rest."""
    policy, inp = make(codec, pose=(1.0, 2.0, math.pi / 2))
    assert offer(inp, twist(vx=0.25), 1, now=10.0)
    op, status = policy.operator_input(10.01, policy.pose)
    np.testing.assert_allclose(op.force, [0.0, 10.0, 0.0], atol=1e-12)
    assert op.intent == pytest.approx(2.5)
    np.testing.assert_allclose(op.desired.q, [1.0, 2.25, math.pi / 2])
    np.testing.assert_array_equal(op.desired.q_dot, np.zeros(3))
    assert status.reason == "active" and policy.lease.holder_id == "ros2-" + GID.hex()


def test_a_twist_beyond_full_scale_keeps_its_direction_and_yaw_saturates(codec):
    """(0.5, 0.5) m/s at ψ = 0 is √2 full deflections along the diagonal: cut to norm 1, (√½, √½); 2 rad/s of 1 at
    full scale: 1."""
    policy, inp = make(codec)
    assert offer(inp, twist(vx=0.5, vy=0.5, wz=2.0), 1, now=10.0)
    op, _ = policy.operator_input(10.01, policy.pose)
    np.testing.assert_allclose(op.force, [20 * math.sqrt(0.5), 20 * math.sqrt(0.5), 5.0])


def test_a_twist_while_a_console_holds_control_is_refused_as_not_holder_and_counted(codec):
    policy, inp = make(codec)
    console = OperatorCommand(operator_id="operator", session_id="c1", seq=1, send_time=WALL + 9.996,
                              joystick=(0.2, 0.0, 0.0), q_d=(-0.9, 3.0, 0.0), qd_d=(0.0,) * 3, qdd_d=(0.0,) * 3,
                              deadman=True, estop=False, control_request=ControlRequest.NONE)
    assert policy.offer(encode_message(console), 10.0, WALL + 10.0)
    assert not offer(inp, twist(vx=0.5), 1, now=10.01)
    assert inp.refused == {"not_holder": 1} and policy.rejections["not_holder"] == 1
    op, _ = policy.operator_input(10.02, policy.pose)
    np.testing.assert_allclose(op.force, [4.0, 0.0, 0.0])           # still the console's 20 · 0.2
    assert policy.lease.holder_id == "operator"


def test_a_second_ros2_publisher_is_another_sender_and_refused_while_the_first_holds(codec):
    policy, inp = make(codec)
    assert offer(inp, twist(vx=0.1), 1, now=10.0)
    assert not offer(inp, twist(vx=-0.5), 1, now=10.01, gid=OTHER)
    assert inp.refused == {"not_holder": 1} and inp.accepted == 1


def test_in_explicit_lease_mode_a_twist_cannot_take_control(codec):
    policy, inp = make(codec, mode="explicit")
    assert not offer(inp, twist(vx=0.3), 1, now=10.0)
    assert inp.refused == {"no_lease": 1} and policy.lease.holder is None


def test_a_twist_arriving_half_a_second_later_than_the_senders_best_is_stale(codec):
    policy, inp = make(codec)
    assert offer(inp, twist(vx=0.3), 1, now=10.0)
    assert not offer(inp, twist(vx=0.3), 2, now=10.7, delay=0.6)    # 0.6 s in transit against 4 ms
    assert inp.refused == {"stale": 1}
    assert offer(inp, twist(vx=0.3), 2, now=10.71)                   # the stale one moved no sequence


def test_a_replayed_twist_is_a_duplicate(codec):
    policy, inp = make(codec)
    assert offer(inp, twist(vx=0.3), 5, now=10.0)
    assert not offer(inp, twist(vx=0.3), 5, now=10.02)
    assert inp.refused == {"duplicate_seq": 1}


def test_a_sender_silent_for_more_than_300_ms_is_hands_off(codec):
    policy, inp = make(codec)
    assert offer(inp, twist(vx=0.3), 1, now=10.0)
    assert not policy.operator_input(10.29, policy.pose)[1].hands_off
    op, status = policy.operator_input(10.31, policy.pose)
    assert status.hands_off and status.reason == "stale"
    np.testing.assert_array_equal(op.force, np.zeros(3))


def test_a_controller_with_an_operators_file_refuses_every_twist(codec):
    """A verifier that would pass anything: a Twist has no signature, so it is never even asked."""
    asked = []
    policy, inp = make(codec, verify=lambda payload, attachment: asked.append(payload) or ("alice", None))
    assert not offer(inp, twist(vx=0.3), 1, now=10.0)
    assert inp.refused == {"ros2_unauthenticated": 1} and policy.rejections["ros2_unauthenticated"] == 1
    assert policy.lease.holder is None and policy.current is None and asked == []


@pytest.mark.parametrize("payload, reason", [
    (twist(vx=math.nan), "ros2_non_finite"),
    (twist(wz=math.inf), "ros2_non_finite"),
    (twist(vx=1e9), "ros2_out_of_range"),
    (twist(vz=-150.0), "ros2_out_of_range"),
    (b"\x00\x01\x00\x00" + b"\x00" * 40, "ros2_bad_cdr"),
])
def test_a_twist_that_is_not_finite_absurd_or_not_a_twist_is_refused_and_never_drives(codec, payload, reason):
    policy, inp = make(codec)
    assert not offer(inp, payload, 1, now=10.0)
    assert inp.refused == {reason: 1} and policy.rejections[reason] == 1
    op, status = policy.operator_input(10.01, policy.pose)
    assert status.reason == "no_command" and not op.force.any() and policy.lease.holder is None


def test_a_twist_without_rmw_zenohs_attachment_is_refused(codec):
    policy, inp = make(codec)
    assert not inp.offer(twist(vx=0.3), 10.0, WALL + 10.0, None)
    assert not inp.offer(twist(vx=0.3), 10.0, WALL + 10.0, b"\x00" * 32)
    assert not inp.offer(twist(vx=0.3), 10.0, WALL + 10.0, struct.pack("<qqB", -1, 0, 16) + GID)  # seq < 0
    assert inp.refused == {"ros2_bad_attachment": 3} and policy.current is None


def test_garbage_from_the_holder_makes_it_hands_off_at_once(codec):
    policy, inp = make(codec)
    assert offer(inp, twist(vx=0.3), 1, now=10.0)
    assert not offer(inp, twist(vx=math.nan), 2, now=10.02)
    op, status = policy.operator_input(10.03, policy.pose)
    assert status.reason == "rejected" and not op.force.any()
