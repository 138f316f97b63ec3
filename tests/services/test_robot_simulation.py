"""The robot simulation without wires: axes on the plant, frame schedule, watchdog → coasting."""
from __future__ import annotations

from collections import Counter

import pytest

from sharedctl.models import OmniRobot
from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.odrive_enums import AxisState, CommandId, ControlMode, InputMode, ODriveError
from sharedctl.services.robot.plant import RobotSimConfig
from sharedctl.services.robot.simulation import MAX_CATCH_UP_STEPS, RobotSimulation, is_own_direction

Q0 = [-0.9, 3.0, 0.0]


def simulation(**config) -> RobotSimulation:
    return RobotSimulation(OmniRobot(), RobotSimConfig(**config), Q0, [0.0, 0.0, 0.0])


def arm(sim: RobotSimulation, now: float) -> None:
    for node in (0, 1, 2):
        sim.receive(cs.ClearErrors(node), now)
        sim.receive(cs.SetControllerMode(node, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH), now)
        sim.receive(cs.SetAxisState(node, AxisState.CLOSED_LOOP_CONTROL), now)


def run(sim, start, seconds, torque=None):
    """Advance at 1 kHz ticks; feed torque to every axis each tick when given. Returns the frames sent."""
    frames = []
    for k in range(1, int(round(seconds * 1000)) + 1):
        now = start + k * 1e-3
        if torque is not None:
            for node in (0, 1, 2):
                sim.receive(cs.SetInputTorque(node, torque), now)
        frames += sim.advance(now)
    return frames


def test_cyclic_frames_default_to_heartbeat_10_hz_and_encoder_500_hz_per_axis():
    counts = Counter((type(f).__name__, f.node_id) for f in run(simulation(), 0.0, 1.0))
    for node in (0, 1, 2):
        assert counts[("Heartbeat", node)] == pytest.approx(10, abs=1)
        assert counts[("GetEncoderEstimates", node)] == pytest.approx(500, abs=1)


def test_the_robot_ignores_only_the_drive_to_host_direction():
    for frame, own in ((cs.Heartbeat(0), True), (cs.GetEncoderEstimates(1, 0.0, 0.0), True),
                       (cs.SetInputTorque(0, 1.0), False), (cs.Estop(2), False),
                       (cs.PollRequest(0, CommandId.GET_ENCODER_ESTIMATES), False)):
        f = cs.encode(frame)
        assert is_own_direction(f.arbitration_id, f.is_remote) is own


def test_armed_torque_turns_the_wheels_forwards():
    sim = simulation()
    arm(sim, 0.0)
    run(sim, 0.0, 0.5, torque=0.3)
    assert all(axis.vel_turns_s > 0.5 and axis.pos_turns > 0.05 for axis in sim.axes)
    assert sim.state.qd[2] > 0                          # equal wheel torques: positive yaw rate


def test_watchdog_trip_disarms_and_the_brakes_bring_the_robot_to_rest():
    sim = simulation()
    arm(sim, 0.0)
    run(sim, 0.0, 0.5, torque=0.3)
    assert sim.plant.brake_torques([not axis.armed for axis in sim.axes]) == (0.0, 0.0, 0.0)   # armed: released
    run(sim, 0.5, 0.11)                                 # silence
    assert all(axis.state == AxisState.IDLE and axis.errors == ODriveError.WATCHDOG_TIMER_EXPIRED for axis in sim.axes)
    assert sim.watchdog_trips == 3
    assert sim.applied_torques() == [0.0, 0.0, 0.0]
    run(sim, 0.61, 0.5)                                 # the brakes stop it in well under a second
    assert all(abs(axis.vel_turns_s) < 1e-3 for axis in sim.axes)


def test_late_command_after_expiry_does_not_revive_the_axis():
    sim = simulation()
    arm(sim, 0.0)
    sim.receive(cs.SetInputTorque(0, 0.3), 0.5)       # 0.5 s after arming, no advance() in between
    assert sim.axes[0].errors == ODriveError.WATCHDOG_TIMER_EXPIRED
    assert sim.applied_torques()[0] == 0.0


def test_a_long_stall_is_skipped_not_replayed():
    sim = simulation()
    sim.advance(1.0)
    assert sim.steps == MAX_CATCH_UP_STEPS
    assert sim.time == pytest.approx(1.0)
    assert sim.skipped_time == pytest.approx(1.0 - MAX_CATCH_UP_STEPS * 1e-3)


def test_frames_for_other_nodes_are_ignored():
    sim = simulation()
    assert sim.receive(cs.PollRequest(7, CommandId.GET_TORQUES), 0.0) == []


def test_a_cyclic_schedule_fires_once_per_period_and_never_in_a_burst_after_a_stall():
    """The rate of the truth messages (and of heartbeats and encoder estimates), on a synthetic clock."""
    from sharedctl.services.lifecycle import Schedule

    schedule = Schedule(100.0)
    fired = [k / 1000.0 for k in range(1000) if schedule.due(k / 1000.0)]     # 1 s polled at 1 kHz
    assert len(fired) == 100
    assert [round(b - a, 9) for a, b in zip(fired, fired[1:])] == [0.01] * 99
    # a 55 ms stall: one message when the loop runs again, then the period from there — no catch-up burst
    after = [t for t in (1.055 + k / 1000.0 for k in range(30)) if schedule.due(t)]
    assert [round(t, 9) for t in after] == [1.055, 1.065, 1.075]
    # a send reached 8 ms late keeps the grid: the next interval is 2 ms, and k sends after one are always more
    # than k − 1 periods later (the guarantee the process test checks on the real clock)
    late = Schedule(100.0)
    fired = [t for t in (0.0, 0.001, 0.018, 0.019, 0.0195, 0.020, 0.021, 0.030, 0.031) if late.due(t)]
    assert fired == [0.0, 0.018, 0.020, 0.030]
    assert all(fired[j] - fired[i] > (j - i - 1) * 0.01 for i in range(len(fired)) for j in range(i + 1, len(fired)))


def test_a_drive_that_restarts_goes_silent_then_comes_back_idle_without_errors_counting_from_zero():
    sim = simulation()
    arm(sim, 0.0)
    run(sim, 0.0, 0.2, torque=1.0)                                 # the wheels turned
    sim.receive(cs.Estop(1), 0.2)
    turns = float(sim.state.wheel_turns[1])
    assert abs(turns) > 0.01 and sim.axes[1].errors == ODriveError.ESTOP_REQUESTED
    sim.restart_drive(1, 0.3, 0.2)
    silent = run(sim, 0.2, 0.29)
    assert silent and not any(getattr(f, "node_id", None) == 1 for f in silent)   # nothing from it while down
    assert sim.receive(cs.SetAxisState(1, AxisState.CLOSED_LOOP_CONTROL), 0.3) == [] and not sim.axes[1].armed
    back = run(sim, 0.49, 0.05)
    beats = [f for f in back if isinstance(f, cs.Heartbeat) and f.node_id == 1]
    estimates = [f for f in back if isinstance(f, cs.GetEncoderEstimates) and f.node_id == 1]
    assert beats and beats[0].axis_state is AxisState.IDLE and beats[0].axis_error == ODriveError.NONE
    assert estimates and abs(estimates[0].pos_estimate) < 0.01    # a new origin where the wheel stands
    assert sim.axes[1].restarts == 1 and sim.axes[1].control_mode is ControlMode.POSITION_CONTROL
