"""Operator commands: the scenario's scripted operator and the keyboard source, as wire messages."""
import numpy as np
import pytest

from sharedctl.protocol.messages import Authority, ControlRequest, LinkHealth, OperatorCommand, RobotState, SetClass
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.protocol.wire_types import ROBOT_DIMS
from sharedctl.services.console.operator import (
    CommandCounter, JoystickCommandSource, ScriptedCommandSource, clip_deflection, new_session_id,
)
from sharedctl.services.scenario_files import load


def state(q=(-0.9, 3.0, 0.0), v=(0.0, 0.0, 0.0)) -> RobotState:
    z = (0.0, 0.0, 0.0)
    return RobotState(
        seq=1, time=0.0, q=q, qd_hat=v, q_ref=q, group_classes=(SetClass.SAFE,), active_group=None,
        authority=Authority.HUMAN, k_s=1.0, k_h=1.0, k_f=0.0, u_h=z, u_f=z, u_s=z, wheel_torques=z,
        theta_hat=z, min_margin=0.1, region_margins=(0.1,), estop_active=False, lease_holder=None,
        link=LinkHealth(operator_latency_ms=0.0, loss_fraction=0.0, staleness_ms=0.0, can_feedback_age_ms=0.0),
    )


@pytest.fixture
def human():
    loop, _, _ = load("paper_convex").closed_loop()
    return loop.human


def test_scripted_deflection_is_the_human_models_at_the_telemetry_pose_and_velocity(human):
    source = ScriptedCommandSource(human)
    q, v = np.array([-0.8, 2.5, 0.0]), np.array([0.01, 0.02, 0.0])
    cmd = source.command(2.0, state(tuple(q), tuple(v)))
    assert np.allclose(cmd.joystick, human.command(2.0, q, v).deflection)


def test_scripted_wish_is_the_desired_trajectory_at_t(human):
    cmd = ScriptedCommandSource(human).command(4.0, state())
    wish = human.desired(4.0)
    assert np.allclose(cmd.q_d, wish.q) and np.allclose(cmd.qd_d, wish.q_dot) and np.allclose(cmd.qdd_d, wish.q_ddot)


def test_scripted_commands_hold_the_deadman_and_count_up(human):
    source = ScriptedCommandSource(human, CommandCounter("op1", "s1"))
    first, second = source.command(0.0, state()), source.command(0.02, state())
    assert (first.seq, second.seq) == (1, 2)
    assert first.deadman and not first.estop
    assert (first.operator_id, first.session_id) == ("op1", "s1")
    assert first.control_request is ControlRequest.NONE


def test_a_deflection_beyond_full_scale_is_clipped_to_the_wire_range(human):
    cmd = ScriptedCommandSource(human).command(0.0, state(q=(-0.9, 4.5, 0.0)))
    assert cmd.joystick[1] == -1.0


def test_clip_deflection_replaces_nan_by_zero():
    assert clip_deflection([np.nan, 2.0, -3.0]) == (0.0, 1.0, -1.0)


def test_scripted_command_round_trips_through_the_codec(human):
    cmd = ScriptedCommandSource(human).command(1.0, state(), send_time=123.0)
    assert decode_message(encode_message(cmd, ROBOT_DIMS), ROBOT_DIMS, expect=OperatorCommand) == cmd


def test_session_ids_are_random_tokens():
    a, b = new_session_id(), new_session_id()
    assert a != b and len(a) == 16


def test_keyboard_command_carries_stick_deadman_estop_and_request():
    source = JoystickCommandSource()
    for key in ("up", "space", "t"):
        source.joystick.press(key, 0.0)
    cmd = source.command(0.0, np.array([0.0, 1.0, 0.0]))
    assert cmd.joystick == (0.0, 0.5, 0.0)
    assert cmd.q_d == pytest.approx((0.0, 1.25, 0.0))
    assert cmd.qd_d == (0.0, 0.0, 0.0) and cmd.deadman and not cmd.estop
    assert cmd.control_request is ControlRequest.TAKE
    source.joystick.press("x", 0.1)
    assert source.command(0.1, np.zeros(3)).estop


def test_send_times_come_from_a_wall_clock_that_never_steps(monkeypatch):
    """A step of the console host's clock must not make its commands look stale or early (replay_guard.py)."""
    import time as time_module

    from sharedctl.services import lifecycle
    before = lifecycle.steady_wall()
    real = time_module.time
    monkeypatch.setattr(time_module, "time", lambda: real() - 2.0)      # the host's clock stepped back 2 s
    source = JoystickCommandSource()
    sent = source.command(0.0, (0.0, 0.0, 0.0)).send_time
    assert before <= sent < before + 1.0
