"""The simulated ODrive axis: a specification of the state machine the controller daemon talks to."""
from __future__ import annotations

import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.odrive_enums import AxisState, CommandId, ControlMode, InputMode, ODriveError, ProcedureResult
from sharedctl.services.robot.axis import TORQUE_CONSTANT, Axis, AxisConfig

NODE = 1


def torque_mode(axis: Axis, now: float = 0.0) -> None:
    axis.handle(cs.SetControllerMode(NODE, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH), now)


def armed_axis(now: float = 0.0) -> Axis:
    axis = Axis(NODE)
    torque_mode(axis, now)
    axis.handle(cs.SetAxisState(NODE, AxisState.CLOSED_LOOP_CONTROL), now)
    return axis


def test_axis_starts_idle_without_errors_and_produces_no_torque():
    axis = Axis(NODE)
    assert axis.state == AxisState.IDLE and axis.errors == ODriveError.NONE
    axis.handle(cs.SetInputTorque(NODE, 1.0), 0.0)
    assert axis.applied_torque() == 0.0


def test_set_axis_state_closed_loop_arms_the_axis():
    axis = armed_axis()
    assert axis.state == AxisState.CLOSED_LOOP_CONTROL
    assert axis.heartbeat() == cs.Heartbeat(NODE, ODriveError.NONE, AxisState.CLOSED_LOOP_CONTROL,
                                            ProcedureResult.SUCCESS, True)


def test_torque_applies_only_in_closed_loop_torque_passthrough():
    axis = Axis(NODE)
    axis.handle(cs.SetAxisState(NODE, AxisState.CLOSED_LOOP_CONTROL), 0.0)
    axis.handle(cs.SetInputTorque(NODE, 1.5), 0.0)
    assert axis.applied_torque() == 0.0          # default POSITION_CONTROL: no torque
    torque_mode(axis)
    axis.handle(cs.SetInputTorque(NODE, 1.5), 0.0)
    assert axis.applied_torque() == 1.5
    axis.handle(cs.SetAxisState(NODE, AxisState.IDLE), 0.0)
    assert axis.applied_torque() == 0.0


def test_torque_is_clamped_to_the_torque_limit():
    axis = Axis(NODE, AxisConfig(torque_limit=2.0))
    torque_mode(axis)
    axis.handle(cs.SetAxisState(NODE, AxisState.CLOSED_LOOP_CONTROL), 0.0)
    axis.handle(cs.SetInputTorque(NODE, -5.0), 0.0)
    assert axis.applied_torque() == -2.0


def test_set_limits_current_limit_lowers_the_torque_limit():
    axis = armed_axis()
    axis.handle(cs.SetLimits(NODE, velocity_limit=100.0, current_limit=2.0), 0.0)
    axis.handle(cs.SetInputTorque(NODE, 10.0), 0.0)
    assert axis.applied_torque() == pytest.approx(2.0 * TORQUE_CONSTANT)


def test_velocity_limit_removes_accelerating_torque_only():
    axis = armed_axis()
    axis.handle(cs.SetLimits(NODE, velocity_limit=2.0, current_limit=100.0), 0.0)
    axis.set_feedback(0.0, 2.5)
    axis.handle(cs.SetInputTorque(NODE, 1.0), 0.0)
    assert axis.applied_torque() == 0.0
    axis.handle(cs.SetInputTorque(NODE, -1.0), 0.0)
    assert axis.applied_torque() == -1.0


def test_estop_sets_estop_requested_and_idles_the_axis():
    axis = armed_axis()
    axis.handle(cs.SetInputTorque(NODE, 1.0), 0.0)
    axis.handle(cs.Estop(NODE), 0.01)
    assert axis.state == AxisState.IDLE
    assert axis.errors == ODriveError.ESTOP_REQUESTED
    assert axis.applied_torque() == 0.0


def test_arming_is_refused_while_an_error_is_active():
    axis = armed_axis()
    axis.handle(cs.Estop(NODE), 0.0)
    axis.handle(cs.SetAxisState(NODE, AxisState.CLOSED_LOOP_CONTROL), 0.0)
    assert axis.state == AxisState.IDLE
    assert axis.procedure_result == ProcedureResult.DISARMED


def test_clear_errors_clears_errors_and_allows_rearming():
    axis = armed_axis()
    axis.handle(cs.Estop(NODE), 0.0)
    axis.handle(cs.ClearErrors(NODE), 0.1)
    assert axis.errors == ODriveError.NONE and axis.state == AxisState.IDLE   # stays disarmed
    assert axis.feedback(CommandId.GET_ERROR).disarm_reason == ODriveError.ESTOP_REQUESTED
    axis.handle(cs.SetAxisState(NODE, AxisState.CLOSED_LOOP_CONTROL), 0.1)
    assert axis.state == AxisState.CLOSED_LOOP_CONTROL


def test_watchdog_trips_after_the_timeout_with_error_and_idle():
    axis = armed_axis(now=0.0)
    axis.handle(cs.SetInputTorque(NODE, 1.0), 0.0)
    assert not axis.tick(0.099)
    assert axis.tick(0.101)
    assert axis.state == AxisState.IDLE
    assert axis.errors & ODriveError.WATCHDOG_TIMER_EXPIRED
    assert axis.heartbeat().axis_error == ODriveError.WATCHDOG_TIMER_EXPIRED
    assert axis.applied_torque() == 0.0
    assert axis.watchdog_trips == 1


def test_feeding_the_watchdog_keeps_the_axis_armed():
    axis = armed_axis(now=0.0)
    for k in range(100):                      # 1 s of torque commands every 50 ms
        now = 0.05 * k
        axis.handle(cs.SetInputTorque(NODE, 0.5), now)
        assert not axis.tick(now + 0.04)
    assert axis.state == AxisState.CLOSED_LOOP_CONTROL
    assert axis.applied_torque() == 0.5


def test_set_input_vel_feeds_the_watchdog_and_sets_torque_feed_forward():
    axis = armed_axis(now=0.0)
    axis.handle(cs.SetInputVel(NODE, 1.0, 0.25), 0.08)
    assert not axis.tick(0.15)
    assert axis.applied_torque() == 0.25


def test_watchdog_does_not_run_while_idle():
    axis = Axis(NODE)
    assert not axis.tick(100.0)
    assert axis.errors == ODriveError.NONE


def test_disabled_watchdog_never_trips():
    axis = Axis(NODE, AxisConfig(watchdog_timeout=0.0))
    torque_mode(axis)
    axis.handle(cs.SetAxisState(NODE, AxisState.CLOSED_LOOP_CONTROL), 0.0)
    assert not axis.tick(10.0)


def test_rearming_resets_the_torque_setpoint():
    axis = armed_axis()
    axis.handle(cs.SetInputTorque(NODE, 1.0), 0.0)
    axis.handle(cs.SetAxisState(NODE, AxisState.IDLE), 0.0)
    axis.handle(cs.SetAxisState(NODE, AxisState.CLOSED_LOOP_CONTROL), 0.0)
    assert axis.applied_torque() == 0.0


@pytest.mark.parametrize("command, expected", [
    (CommandId.GET_ENCODER_ESTIMATES, cs.GetEncoderEstimates(NODE, 2.5, -0.5)),
    (CommandId.GET_ERROR, cs.GetError(NODE, ODriveError.NONE, ODriveError.NONE)),
    (CommandId.GET_IQ, cs.GetIq(NODE, 1.0 / TORQUE_CONSTANT, 1.0 / TORQUE_CONSTANT)),
    (CommandId.GET_TORQUES, cs.GetTorques(NODE, 1.0, 1.0)),
    (CommandId.GET_BUS_VOLTAGE_CURRENT, cs.GetBusVoltageCurrent(NODE, 24.0, 1.0 * -0.5 * 2 * 3.141592653589793 / 24.0)),
])
def test_rtr_poll_answers_each_get_frame(command, expected):
    axis = armed_axis()
    axis.set_feedback(2.5, -0.5)
    axis.handle(cs.SetInputTorque(NODE, 1.0), 0.0)
    assert axis.handle(cs.PollRequest(NODE, command), 0.0) == [expected]


def test_get_error_reports_watchdog_as_active_error_and_disarm_reason():
    axis = armed_axis()
    axis.tick(1.0)
    reply = axis.handle(cs.PollRequest(NODE, CommandId.GET_ERROR), 1.0)[0]
    assert reply.active_errors == ODriveError.WATCHDOG_TIMER_EXPIRED
    assert reply.disarm_reason == ODriveError.WATCHDOG_TIMER_EXPIRED
