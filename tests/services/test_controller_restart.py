"""Restart safety (services/controller/checkpoint.py, resume.py, the daemon's STARTING and HELD modes): a
controller arms only drives it disarmed itself in this life; one that follows a failed controller resumes from
its checkpoint and keeps the drives disarmed until an operator takes control; a latched Estop survives it; with
no trustworthy pose arming is refused, and why is said."""
import math
import os
from pathlib import Path

import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.messages import ControlRequest
from sharedctl.protocol.odrive_enums import AxisState, ODriveError
from sharedctl.services.controller import checkpoint as checkpoints
from sharedctl.services.controller.daemon import ControllerDaemon, DaemonConfig, Mode
from sharedctl.services.controller.resume import decide
from sharedctl.services.scenario_files import load

from .test_controller_loop import MemoryBus, MemorySession, events, message, operator

Q0 = (-0.9, 3.0, 0.0)
BOOT = "boot-a"


def saved(**changes):
    fields = dict(robot_id="unit", scenario="paper_convex", q=(0.2, 1.5, 0.1), wheel_turns=(1.0, -2.0, 0.5),
                  theta_hat=(18.0, 1.0, 2.0), estop=False, reason="", wall=1000.0, monotonic=50.0, boot_id=BOOT,
                  seq=7)
    fields.update(changes)
    return checkpoints.Checkpoint(**fields)


# ----------------------------------------------------------------------------- the file
def test_a_checkpoint_reads_back_as_written_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "c.checkpoint"
    checkpoints.write(path, saved())
    assert checkpoints.read(path) == saved()
    assert os.listdir(tmp_path) == ["c.checkpoint"]
    assert checkpoints.read(tmp_path / "absent") is None


@pytest.mark.parametrize("spoil", [
    lambda b: b[: len(b) // 2],                                  # torn
    lambda b: b.replace(b'"seq":7', b'"seq":8'),                # a field changed: the CRC says so
    lambda b: b.replace(b'"version":1', b'"version":2'),
    lambda b: b"\x00\xff junk",
])
def test_a_spoiled_checkpoint_is_an_error_never_a_pose(tmp_path, spoil):
    path = tmp_path / "c.checkpoint"
    checkpoints.write(path, saved())
    path.write_bytes(spoil(path.read_bytes()))
    with pytest.raises(checkpoints.CheckpointError):
        checkpoints.read(path)


def test_the_age_runs_on_the_monotonic_clock_within_a_boot_so_a_wall_clock_step_cannot_make_it_young():
    ck = saved()
    assert ck.age(wall=1000.0 - 3600.0, monotonic=52.5, boot_id=BOOT) == pytest.approx(2.5)   # wall stepped back 1 h
    assert ck.age(wall=1004.0, monotonic=1.0, boot_id="boot-b") == pytest.approx(4.0)        # another boot: wall
    assert ck.age(wall=900.0, monotonic=1.0, boot_id="boot-b") == math.inf                   # negative: no age


# ----------------------------------------------------------------------------- the decision
def start(source, ck, turns=(1.1, -1.9, 0.5), errors=(0, 0, 0), age=2.0):
    return decide(source, ck, robot_id="unit", scenario="paper_convex", q0=Q0, turns=turns, errors=errors, age=age)


def test_a_checkpoint_of_a_failed_controller_is_resumed_disarmed_until_a_take():
    s = start("checkpoint", saved())
    assert (s.action, s.q, s.wheel_turns, s.theta_hat) == ("hold", saved().q, saved().wheel_turns, saved().theta_hat)
    latched = start("checkpoint", saved(estop=True, reason="feedback lost"), errors=(ODriveError.ESTOP_REQUESTED,) * 3)
    assert latched.action == "estop" and "feedback lost" in latched.text
    on_a_drive = start("checkpoint", saved(), errors=(0, ODriveError.ESTOP_REQUESTED, 0))   # sent after the last write
    assert on_a_drive.action == "estop" and "drives [1]" in on_a_drive.text


@pytest.mark.parametrize("ck, kwargs, why", [
    (checkpoints.CheckpointError("CRC mismatch"), {}, "CRC mismatch"),
    (saved(robot_id="other"), {}, "robot 'other'"),
    (saved(scenario="paper_nonconvex"), {}, "scenario"),
    (saved(), {"age": 61.0}, "61.0 s old"),
    (saved(), {"age": math.inf}, "inf s old"),
    (saved(), {"turns": (1.0, -2.0, -9.0), "age": 0.5}, "wheel 2"),     # a drive that restarted reads anew
    (None, {"errors": (0, ODriveError.WATCHDOG_TIMER_EXPIRED, 0)}, "WATCHDOG_TIMER_EXPIRED"),
    (saved(ended=True), {"errors": (ODriveError.ESTOP_REQUESTED, 0, 0)}, "ended on purpose"),
])
def test_without_a_trustworthy_pose_arming_is_refused_and_the_reason_given(ck, kwargs, why):
    s = start("checkpoint", ck, **kwargs)
    assert s.action == "refuse" and why in s.text and "--pose scenario" in s.text


def test_drives_armed_in_the_checkpoint_without_an_error_now_were_restarted_and_the_checkpoint_is_refused():
    """A controller that dies with the drives armed leaves their watchdogs expired. Clean drives say they were
    restarted (power cycle, a new simulation): their encoders no longer continue the checkpoint's."""
    armed = saved(armed=True)
    watchdog = ODriveError.WATCHDOG_TIMER_EXPIRED
    assert start("checkpoint", armed, errors=(watchdog, watchdog, watchdog)).action == "hold"
    refused = start("checkpoint", armed, errors=(watchdog, 0, watchdog))
    assert refused.action == "refuse" and "drives [1] report no error" in refused.text
    assert start("checkpoint", saved(armed=False)).action == "hold"       # held or idle then: no witness
    estop = ODriveError.ESTOP_REQUESTED
    assert start("checkpoint", saved(estop=True, reason="x"), errors=(estop, estop, estop)).action == "estop"
    assert start("checkpoint", saved(estop=True, reason="x"), errors=(0, 0, 0)).action == "refuse"


def test_a_first_start_or_a_declared_pose_arms_at_the_scenario_pose_but_keeps_a_drives_estop():
    assert start("checkpoint", None).action == "arm"
    assert start("checkpoint", saved(ended=True)).action == "arm"
    declared = start("scenario", saved())                       # re-homing overrides the checkpoint
    assert (declared.action, declared.q, declared.wheel_turns) == ("arm", Q0, (1.1, -1.9, 0.5))
    assert start("scenario", None, errors=(0, 0, ODriveError.ESTOP_REQUESTED)).action == "estop"


# ----------------------------------------------------------------------------- the daemon
def daemon(path, pose="checkpoint"):
    loop, q0, _ = load("paper_convex").closed_loop("ce")
    config = DaemonConfig(robot_id="unit", verbose=False, scenario="paper_convex", pose=pose, checkpoint=path)
    d = ControllerDaemon(config, loop, q0, MemoryBus(), MemorySession())
    d.master.clock = lambda: d.clock_now
    d.clock_now = 10.0
    return d


def feed(d, now, turns, state=AxisState.IDLE, error=ODriveError.NONE, vel=(0.0, 0.0, 0.0)):
    for n in (0, 1, 2):
        d.master.handle(message(cs.GetEncoderEstimates(n, turns[n], vel[n])), now)
        d.master.handle(message(cs.Heartbeat(n, error, state)), now)


def frames(d, kind):
    return [f for f in d.master.bus.take() if isinstance(f, kind)]


def run_first_life(path, turns_moved=(0.4, -0.2, 0.1)):
    """A controller that starts, arms, drives the wheels by `turns_moved` and writes its checkpoint."""
    d = daemon(path)
    d.begin()
    feed(d, 10.001, (0.0, 0.0, 0.0))
    d.tick(10.002)
    assert d.mode is Mode.ARMING
    feed(d, 10.003, (0.0, 0.0, 0.0), state=AxisState.CLOSED_LOOP_CONTROL)
    d.tick(10.004)
    assert d.mode is Mode.RUNNING
    steps = 250                                                    # 0.5 s at a steady wheel speed
    vel = tuple(t / (steps * 0.002) for t in turns_moved)
    for k in range(1, steps + 1):
        now = 10.004 + 0.002 * k
        feed(d, now, tuple(t * k / steps for t in turns_moved), state=AxisState.CLOSED_LOOP_CONTROL, vel=vel)
        d.tick(now + 0.0005)
    d.save_checkpoint(now + 0.0005)
    assert d.continuity.writer.flush()
    return d


def test_a_controller_following_a_dead_one_resumes_its_pose_and_arms_only_on_an_operators_take(tmp_path):
    path = tmp_path / "controller-unit.checkpoint"
    first = run_first_life(path)
    q_then = first.q.copy()
    assert math.dist(q_then, Q0) > 0.05                          # it had moved
    # killed here: no shutdown; the drives' watchdogs expire. The robot rolled on by (0.02, 0.01, -0.01) turns
    second = daemon(path)
    second.begin()
    assert frames(second, cs.SetAxisState) == [cs.SetAxisState(n, AxisState.IDLE) for n in (0, 1, 2)]
    feed(second, 10.001, (0.42, -0.19, 0.09), error=ODriveError.WATCHDOG_TIMER_EXPIRED)
    second.tick(10.002)
    assert second.mode is Mode.HELD
    expected, _ = first.odometry.update(second.master.estimates())   # the dead one's odometry, carried on
    assert second.q == pytest.approx(expected, abs=1e-12)
    assert tuple(second.state.theta_hat) == pytest.approx(tuple(first.state.theta_hat))
    # operator commands without a take: still disarmed; IDLE repeated; no Clear_Errors, no closed loop, no torque
    for k in range(1, 400):
        now = 10.002 + 0.002 * k
        operator(second, k, now)
        feed(second, now, (0.42, -0.19, 0.09), error=ODriveError.WATCHDOG_TIMER_EXPIRED)
        second.tick(now)
    sent = second.master.bus.take()
    assert second.mode is Mode.HELD
    assert not any(isinstance(f, (cs.ClearErrors, cs.SetInputTorque)) for f in sent)
    assert not any(isinstance(f, cs.SetAxisState) and f.requested_state is AxisState.CLOSED_LOOP_CONTROL for f in sent)
    assert sum(isinstance(f, cs.SetAxisState) for f in sent) >= 3 * 2     # IDLE again every 0.5 s
    operator(second, 400, 10.9, request=ControlRequest.TAKE)
    feed(second, 10.9, (0.42, -0.19, 0.09), error=ODriveError.WATCHDOG_TIMER_EXPIRED)
    second.tick(10.9)
    assert second.mode is Mode.ARMING and cs.ClearErrors(0) in second.master.bus.take()


def test_an_estop_latched_before_the_restart_stays_latched_and_is_repeated(tmp_path):
    path = tmp_path / "controller-unit.checkpoint"
    first = run_first_life(path)
    operator(first, 1, 10.007, estop=True)
    first.tick(10.007)
    assert first.mode is Mode.ESTOPPED and first.continuity.writer.flush()
    assert checkpoints.read(path).estop                           # offered at once, not 50 ms later
    second = daemon(path)
    second.begin()
    feed(second, 10.001, (0.4, -0.2, 0.1), error=ODriveError.ESTOP_REQUESTED)
    second.tick(10.002)
    assert second.mode is Mode.ESTOPPED
    assert frames(second, cs.Estop) == [cs.Estop(n) for n in (0, 1, 2)]
    for now in (10.3, 10.6, 11.2):
        feed(second, now, (0.4, -0.2, 0.1), error=ODriveError.ESTOP_REQUESTED)
        second.tick(now)
    assert len(frames(second, cs.Estop)) == 3 * 2                   # every 0.5 s while latched
    assert any("latched at start" in e.text for e in events(second))


def test_a_refused_start_arms_on_no_take_and_no_estop_clearance(tmp_path):
    d = daemon(tmp_path / "absent.checkpoint")
    d.begin()
    feed(d, 10.001, (3.0, 1.0, -2.0), error=ODriveError.WATCHDOG_TIMER_EXPIRED)   # a controller was here
    d.tick(10.002)
    assert d.mode is Mode.HELD and "WATCHDOG_TIMER_EXPIRED" in d.refusal
    for k, (estop, request) in enumerate([(False, ControlRequest.TAKE), (True, ControlRequest.NONE),
                                          (False, ControlRequest.TAKE)], start=1):
        now = 10.002 + 0.01 * k
        operator(d, k, now, estop=estop, request=request)
        feed(d, now, (3.0, 1.0, -2.0), error=ODriveError.WATCHDOG_TIMER_EXPIRED)
        d.tick(now)
    sent = d.master.bus.take()
    assert d.mode is Mode.ESTOPPED
    assert not any(isinstance(f, cs.ClearErrors) or (isinstance(f, cs.SetAxisState)
                   and f.requested_state is AxisState.CLOSED_LOOP_CONTROL) for f in sent)
    assert sum("arming refused" in e.text for e in events(d)) >= 2
    d.save_checkpoint(10.1, force=True)
    assert not (tmp_path / "absent.checkpoint").exists()          # a refused pose is never written as evidence


def test_drives_still_in_closed_loop_are_disarmed_before_anything_else(tmp_path):
    d = daemon(tmp_path / "c.checkpoint", pose="scenario")
    d.begin()
    d.master.bus.take()
    for k in range(60):                                            # 120 ms of drives that stay armed
        now = 10.001 + 0.002 * k
        feed(d, now, (0.0, 0.0, 0.0), state=AxisState.CLOSED_LOOP_CONTROL)
        d.tick(now)
    sent = d.master.bus.take()
    assert d.mode is Mode.STARTING
    assert sent and all(f == cs.SetAxisState(f.node_id, AxisState.IDLE) for f in sent)
    feed(d, 10.2, (0.0, 0.0, 0.0))
    d.tick(10.2)
    assert d.mode is Mode.ARMING


def test_a_controller_stopped_on_purpose_hands_the_robot_back(tmp_path):
    path = tmp_path / "c.checkpoint"
    first = run_first_life(path)
    first.shutdown(ended=True)
    assert checkpoints.read(path).ended
    second = daemon(path)
    second.begin()
    feed(second, 10.001, (0.4, -0.2, 0.1))
    second.tick(10.002)
    assert second.mode is Mode.ARMING and tuple(second.q) == pytest.approx(Q0)


def test_the_default_checkpoint_lives_in_the_state_folder(monkeypatch, tmp_path):
    monkeypatch.setenv("SHAREDCTL_STATE_DIR", str(tmp_path))
    assert checkpoints.default_path("r7") == tmp_path / "controller-r7.checkpoint"
    monkeypatch.delenv("SHAREDCTL_STATE_DIR")
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert checkpoints.default_path("r7") == Path(tmp_path / "xdg" / "sharedctl" / "controller-r7.checkpoint")


# ----------------------------------------------------------------------------- a drive that restarts
def reboot_wheel_1(d, t0, before, after, vel_before=0.0, vel_after=0.0, gap=0.6):
    """Wheel 1's drive falls silent for `gap` s and comes back counting from `after` turns (the others steady)."""
    for k in range(20):                                   # steady frames, the wheel at `before`
        t = t0 + 0.002 * k
        d.master.handle(message(cs.GetEncoderEstimates(1, before + vel_before * 0.002 * k, vel_before)), t)
        for n in (0, 2):
            d.master.handle(message(cs.GetEncoderEstimates(n, 0.5, 0.0)), t)
        d.tick(t + 0.0002)
    t = t0 + 0.04 + gap
    for k in range(10):                                   # back, from its new origin
        now = t + 0.002 * k
        d.master.handle(message(cs.GetEncoderEstimates(1, after + vel_after * 0.002 * k, vel_after)), now)
        for n in (0, 2):
            d.master.handle(message(cs.GetEncoderEstimates(n, 0.5, 0.0)), now)
        d.master.handle(message(cs.Heartbeat(1, ODriveError.NONE, AxisState.IDLE)), now)
        d.tick(now + 0.0002)
    return now


def test_an_encoder_that_restarts_by_less_than_two_turns_at_rest_moves_nothing(tmp_path):
    d = daemon(None, pose="scenario")
    d.begin()
    feed(d, 10.001, (0.5, 1.3, 0.5))
    d.tick(10.002)
    q_before = d.q.copy()
    reboot_wheel_1(d, 10.004, before=1.3, after=0.0)      # 1.3 turns ≈ 0.32 m of wheel travel, if integrated
    assert d.q == pytest.approx(q_before, abs=1e-9)
    assert d.odometry.discontinuities == 1 and d.odometry.uncertainty == 0.0 and d.refusal is None
    assert any("encoder jumped from 1.300 to 0.000" in e.text for e in events(d))


def test_an_encoder_that_restarts_while_its_wheel_turns_makes_the_pose_unknown_and_arming_refused(tmp_path):
    d = daemon(None, pose="scenario")
    d.begin()
    feed(d, 10.001, (0.5, 1.3, 0.5))
    d.tick(10.002)
    now = reboot_wheel_1(d, 10.004, before=1.3, after=0.0, vel_before=2.0, vel_after=0.0)
    assert d.odometry.uncertainty > 0.01 and "arming refused" in d.refusal
    assert d.mode is Mode.ESTOPPED
    d.master.bus.take()
    operator(d, 1, now + 0.002, request=ControlRequest.TAKE)
    feed(d, now + 0.002, (0.5, 0.0, 0.5))
    d.tick(now + 0.002)
    assert d.mode is Mode.ESTOPPED and not any(isinstance(f, cs.ClearErrors) for f in d.master.bus.take())
