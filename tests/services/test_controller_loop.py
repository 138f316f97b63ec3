"""The daemon's per-period logic (services/controller/daemon.py), stepped by hand with an in-memory
bus and an in-memory Zenoh session: arming, control, estops, re-arm, NonFiniteCommand."""
import math
import time

import can
import numpy as np
import pytest

from sharedctl.models import OmniRobot
from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.messages import ControlRequest, Event, OperatorCommand, RobotState
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.protocol.odrive_enums import AxisState, ODriveError
from sharedctl.services.controller.daemon import ControllerDaemon, DaemonConfig, Mode
from sharedctl.services.scenario_files import load
from sharedctl.shared_controller import NonFiniteCommand

PERIOD = 0.002


class MemoryBus:
    def __init__(self):
        self.sent = []

    def send(self, msg, timeout=None):
        self.sent.append(cs.decode(msg.arbitration_id, bytes(msg.data), msg.is_remote_frame, dlc=msg.dlc))

    def recv(self, timeout=None):
        return None

    def take(self):
        sent, self.sent = self.sent, []
        return sent


class Publisher:
    def __init__(self):
        self.payloads = []

    def put(self, payload):
        self.payloads.append(payload)

    def undeclare(self):
        pass


class Subscription(Publisher):
    """A subscriber with a channel handler: `try_recv()` hands out what was put in `samples`, oldest first."""

    def __init__(self, handler):
        super().__init__()
        self.handler, self.samples = handler, []

    def try_recv(self):
        return self.samples.pop(0) if self.samples else None


class MemorySession:
    """declare_publisher / declare_subscriber / declare_queryable / liveliness().declare_token, kept in dicts."""

    def __init__(self):
        self.publishers, self.subscriptions = {}, {}

    def declare_publisher(self, key, **qos):
        return self.publishers.setdefault(key, Publisher())

    def declare_subscriber(self, key, handler):
        return self.subscriptions.setdefault(key, Subscription(handler))

    def declare_queryable(self, key, handler):
        return self.subscriptions.setdefault(key, Subscription(handler))

    def liveliness(self):
        return self

    def declare_token(self, key):
        return Publisher()


def message(frame):
    f = cs.encode(frame)
    return can.Message(arbitration_id=f.arbitration_id, data=f.data, dlc=f.dlc, is_extended_id=False)


def make_daemon():
    """The paper_convex CE daemon on an in-memory bus and session, its CAN master's clock at 10 s."""
    loop, q0, _ = load("paper_convex").closed_loop("ce")
    d = ControllerDaemon(DaemonConfig(robot_id="unit", verbose=False), loop, q0, MemoryBus(), MemorySession())
    d.master.clock = lambda: d.clock_now
    d.clock_now = 10.0
    start(d)
    return d


def start(d, now=10.0, state=AxisState.IDLE, error=ODriveError.NONE):
    """The start-up: IDLE to every axis, the axes heard idle, the start decided (a first start: ARMING)."""
    d.begin()
    feed(d, now + 0.0005, state=state, error=error)
    d.tick(now + 0.0006)
    d.master.bus.take()


@pytest.fixture
def daemon():
    return make_daemon()


def feed(d, now, state=AxisState.CLOSED_LOOP_CONTROL, error=ODriveError.NONE, v_turns=(0.0, 0.0, 0.0), heartbeat=True):
    for n in (0, 1, 2):
        d.master.handle(message(cs.GetEncoderEstimates(n, 0.0, v_turns[n])), now)
        if heartbeat:
            d.master.handle(message(cs.Heartbeat(n, error, state)), now)


def arm(d):
    d.master.request_arming()
    d.bus_frames = d.master.bus.take()
    feed(d, 10.001)
    d.tick(10.002)
    assert d.mode is Mode.RUNNING


def events(d):
    return [decode_message(p, expect=Event) for p in d.session.publishers["sharedctl/v1/unit/events"].payloads]


def operator(d, seq, now, joystick=(0.0, 0.0, 0.0), estop=False, request=ControlRequest.NONE):
    cmd = OperatorCommand(operator_id="op", session_id="s", seq=seq, send_time=1.0, joystick=joystick,
                          q_d=(-0.9, 3.0, 0.0), qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True,
                          estop=estop, control_request=request)
    d.policy.offer(encode_message(cmd), now)


def test_arming_sends_zero_torque_until_every_axis_reports_closed_loop(daemon):
    daemon.master.request_arming()
    daemon.master.bus.take()
    daemon.tick(10.001)
    assert daemon.mode is Mode.ARMING
    assert daemon.master.bus.take() == [cs.SetInputTorque(n, 0.0) for n in (0, 1, 2)]
    feed(daemon, 10.002)
    daemon.tick(10.003)
    assert daemon.mode is Mode.RUNNING


def test_running_turns_the_operator_force_into_wheel_torques(daemon):
    arm(daemon)
    daemon.master.bus.take()
    operator(daemon, 1, 10.003, joystick=(0.5, 0.0, 0.0))
    feed(daemon, 10.004, heartbeat=False)
    daemon.tick(10.004)
    sent = daemon.master.bus.take()
    tau = np.array([f.input_torque for f in sent])
    expected = OmniRobot().wheel_torques(np.array([-0.9, 3.0, 0.0]), np.array([10.0, 0.0, 0.0]))
    np.testing.assert_allclose(tau, expected, rtol=1e-6)
    assert [f.node_id for f in sent] == [0, 1, 2]


def test_torques_above_the_limit_are_scaled_down_keeping_their_direction(daemon):
    daemon.config.torque_limit = 0.05
    arm(daemon)
    daemon.master.bus.take()
    operator(daemon, 1, 10.003, joystick=(1.0, 0.5, 0.0))
    daemon.tick(10.003)
    tau = np.array([f.input_torque for f in daemon.master.bus.take()])
    expected = OmniRobot().wheel_torques(np.array([-0.9, 3.0, 0.0]), np.array([20.0, 10.0, 0.0]))
    assert np.max(np.abs(tau)) == pytest.approx(0.05, rel=1e-6)
    np.testing.assert_allclose(tau / np.max(np.abs(tau)), expected / np.max(np.abs(expected)), rtol=1e-5)


def test_feedback_older_than_50_ms_estops_every_axis_and_stops_commanding(daemon):
    arm(daemon)
    daemon.master.bus.take()
    daemon.tick(10.0505)                  # last estimate at 10.001: 49.5 ms, still fine
    assert daemon.mode is Mode.RUNNING
    daemon.master.bus.take()
    daemon.tick(10.0525)
    assert daemon.mode is Mode.ESTOPPED
    assert daemon.master.bus.take() == [cs.Estop(n) for n in (0, 1, 2)]
    daemon.tick(10.0545)
    assert daemon.master.bus.take() == [cs.Estop(n) for n in (0, 1, 2)]     # the Estop again, no torque
    assert any(e.kind.value == "estop" and "CAN feedback lost" in e.text for e in events(daemon))


def test_a_loop_silent_for_the_watchdog_time_less_a_margin_estops_instead_of_driving_on(daemon):
    """A stall of the controller (a hang, a starved host) near T_w = 0.1 s: with torque frames lost around it, one
    drive's watchdog may have expired while the others were fed, and driving on would push the robot on the wheels
    left (a demo with a 99 ms hang, 25 ms of CAN delay and 20 % loss spun the robot 3 rad past its yaw limit). So
    the first tick after 80 ms without torque frames (T_w less ten periods of frames lost around the stall) estops;
    a shorter stall resumes."""
    arm(daemon)
    feed(daemon, 10.0035)
    daemon.tick(10.004)
    assert daemon.mode is Mode.RUNNING and daemon.silence_limit == pytest.approx(0.08)
    feed(daemon, 10.0830)
    daemon.tick(10.0835)                   # 79.5 ms without a step: resumes
    assert daemon.mode is Mode.RUNNING
    feed(daemon, 10.1635)
    daemon.master.bus.take()
    daemon.tick(10.1645)                   # 81 ms
    assert daemon.mode is Mode.ESTOPPED
    assert daemon.master.bus.take() == [cs.Estop(n) for n in (0, 1, 2)]
    assert any(e.kind.value == "estop" and "no torque sent for 81 ms" in e.text for e in events(daemon))


def test_the_estop_goes_out_every_tick_for_100_ms_then_every_half_second(daemon):
    """A lost Estop frame must not leave a drive on its last torque until its watchdog: under 20 % CAN loss one
    frame misses a given drive one time in five, fifty in a row one time in 10³⁵."""
    arm(daemon)
    daemon.master.bus.take()
    operator(daemon, 1, 10.003, estop=True)
    daemon.tick(10.004)
    assert daemon.mode is Mode.ESTOPPED and daemon.master.bus.take() == [cs.Estop(n) for n in (0, 1, 2)]
    sent_at = []
    for k in range(1, 320):
        daemon.tick(10.0045 + 0.002 * k)        # half a period off the burst's end, so no tick lands on it
        frames = daemon.master.bus.take()
        assert all(isinstance(f, cs.Estop) for f in frames)
        if frames:
            assert frames == [cs.Estop(n) for n in (0, 1, 2)]
            sent_at.append(k)
    # every tick up to 100 ms after the estop, then 0.5 s after the last of them
    assert sent_at == list(range(1, 50)) + [49 + 250]


def test_an_axis_error_while_running_estops(daemon):
    arm(daemon)
    feed(daemon, 10.003, state=AxisState.IDLE, error=ODriveError.WATCHDOG_TIMER_EXPIRED)
    daemon.tick(10.004)
    assert daemon.mode is Mode.ESTOPPED
    kinds = {e.kind.value for e in events(daemon)}
    assert {"watchdog_trip", "estop"} <= kinds


def test_non_finite_command_sends_zero_torque_then_estop(daemon, monkeypatch):
    arm(daemon)
    daemon.master.bus.take()

    def broken(*args, **kwargs):
        raise NonFiniteCommand("test")
    monkeypatch.setattr(daemon.controller, "step", broken)
    daemon.tick(10.003)
    assert daemon.master.bus.take() == [cs.SetInputTorque(n, 0.0) for n in (0, 1, 2)] + [cs.Estop(n) for n in (0, 1, 2)]
    assert daemon.mode is Mode.ESTOPPED
    assert any("non-finite" in e.text for e in events(daemon))


def test_operator_estop_latches_and_a_later_take_rearms(daemon):
    arm(daemon)
    operator(daemon, 1, 10.003, estop=True)
    daemon.tick(10.003)
    assert daemon.mode is Mode.ESTOPPED
    operator(daemon, 2, 10.004)                                   # estop released, but no take yet
    feed(daemon, 10.004, heartbeat=False)
    daemon.tick(10.004)
    assert daemon.mode is Mode.ESTOPPED
    daemon.master.bus.take()
    operator(daemon, 3, 10.005, request=ControlRequest.TAKE)
    feed(daemon, 10.005, heartbeat=False)
    daemon.tick(10.005)
    assert daemon.mode is Mode.ARMING
    assert cs.ClearErrors(0) in daemon.master.bus.take()
    assert any(e.kind.value == "estop_cleared" for e in events(daemon))


def test_robot_state_is_published_with_the_link_health(daemon):
    arm(daemon)
    operator(daemon, 1, 10.003, joystick=(0.0, 0.25, 0.0))
    feed(daemon, 10.004, heartbeat=False)
    daemon.tick(10.005)
    daemon.telemetry.publish_state(10.005)
    state = decode_message(daemon.session.publishers["sharedctl/v1/unit/state"].payloads[-1], expect=RobotState)
    assert state.u_h == pytest.approx((0.0, 5.0, 0.0)) and state.lease_holder == "op"
    assert state.link.staleness_ms == pytest.approx(2.0) and state.link.can_feedback_age_ms == pytest.approx(1.0)
    assert math.isclose(state.k_s, 1.0) and not state.estop_active


def test_robot_state_reports_when_the_holder_was_granted_the_lease_on_its_wall_clock(daemon):
    arm(daemon)
    operator(daemon, 1, 10.003)                                   # the implicit take, at monotonic 10.003
    operator(daemon, 2, 10.004)                                   # a renewal
    feed(daemon, 10.004, heartbeat=False)
    daemon.tick(10.005)
    daemon.telemetry.publish_state(10.005)
    state = decode_message(daemon.session.publishers["sharedctl/v1/unit/state"].payloads[-1], expect=RobotState)
    assert state.lease_since == pytest.approx(10.003 + time.time() - time.monotonic(), abs=0.01)


def test_robot_state_in_three_stages_sends_what_was_captured_in_its_first(daemon):
    """A RobotState's stage 0 captures (and works out q_r), 1 builds, 2 puts (telemetry_schedule.py): one message,
    with the values of the period that captured it, whatever the ticks between the stages change; the same as
    publish_state's."""
    states = daemon.session.publishers["sharedctl/v1/unit/state"].payloads
    arm(daemon)
    operator(daemon, 1, 10.003, joystick=(0.0, 0.25, 0.0))
    feed(daemon, 10.004, heartbeat=False)
    daemon.tick(10.005)
    daemon.telemetry.publish_state(10.005)
    at_once = decode_message(states[-1], expect=RobotState)
    daemon.telemetry.stage(0, 10.005)
    operator(daemon, 2, 10.006, joystick=(0.5, 0.0, 0.0))         # the next period: another command, another u_h
    feed(daemon, 10.006, heartbeat=False)
    daemon.tick(10.007)
    daemon.telemetry.stage(1, 10.007)
    sent = len(states)
    daemon.telemetry.stage(2, 10.009)
    assert len(states) == sent + 1
    staged = decode_message(states[-1], expect=RobotState)
    assert staged.seq == at_once.seq + 1 and staged.u_h == pytest.approx((0.0, 5.0, 0.0))
    assert staged.q_ref == pytest.approx(at_once.q_ref, nan_ok=True)
    assert staged.wheel_torques == pytest.approx(at_once.wheel_torques) and daemon.u_s.tolist() != list(staged.u_s)
    daemon.telemetry.stage(2, 10.011)                                # nothing built since: nothing sent
    assert len(states) == sent + 1


def test_robot_state_and_heartbeats_go_out_at_their_rates_on_the_clock_whatever_the_loop_rate(daemon):
    """`states` and `heartbeats` (telemetry_schedule.py), once a period: 50 RobotStates and one Heartbeat a second
    whether the loop ticks at 500 Hz or, missing every other deadline, at 250 Hz (a count of ticks would halve
    both); every RobotState whole and in sequence."""
    states = daemon.session.publishers["sharedctl/v1/unit/state"].payloads
    beats = daemon.session.publishers["sharedctl/v1/unit/alive/controller"].payloads
    arm(daemon)
    for start, period in ((20.0, 0.002), (30.0, 0.004)):
        sent, beat = len(states), len(beats)
        for k in range(round(3.0 / period)):
            daemon.telemetry.states(start + k * period)
            daemon.telemetry.heartbeats(start + k * period)
        assert len(states) - sent in (149, 150, 151) and len(beats) - beat == 3
    seqs = [decode_message(p, expect=RobotState).seq for p in states]
    assert seqs == list(range(1, len(seqs) + 1))


def test_a_robot_state_stage_that_fails_is_reported_and_its_message_dropped(daemon, monkeypatch):
    from sharedctl.services.controller import telemetry_schedule

    states = daemon.session.publishers["sharedctl/v1/unit/state"].payloads
    arm(daemon)

    def broken(*args):
        raise ValueError("no state")

    monkeypatch.setattr(telemetry_schedule, "robot_state", broken)
    for stage in range(3):
        daemon.telemetry.stage(stage, 10.003 + 0.002 * stage)
    assert states == [] and any("RobotState not sent: ValueError: no state" in e.text for e in events(daemon))


class TimedBus(MemoryBus):
    """recv() hands out queued (arrival time, message) pairs on the daemon's fake clock: waiting for one
    moves the clock to its arrival; a timeout with nothing due moves it by the timeout."""

    def __init__(self, daemon):
        super().__init__()
        self.daemon, self.queue = daemon, []

    def recv(self, timeout=None):
        now = self.daemon.clock_now
        if self.queue and self.queue[0][0] <= now + (timeout or 0.0):
            at, msg = self.queue.pop(0)
            self.daemon.clock_now = max(now, at)
            return msg
        self.daemon.clock_now = now + (timeout or 0.0)
        return None


def running_with_drives_every(d, interval, periods=8):
    """Armed, with encoder frames `interval` apart so far (the drives' measured period)."""
    arm(d)
    d.master.use_bus(TimedBus(d))
    for k in range(periods):
        feed(d, 10.0 - interval * (periods - k), heartbeat=False)
    d.last_tick_at = 10.0 - 0.5 * interval      # the previous tick saw the last set
    d.clock_now = 10.0


def test_a_tick_whose_estimates_are_late_waits_for_them_and_no_longer(daemon):
    running_with_drives_every(daemon, PERIOD)
    for n in (0, 1, 2):
        daemon.master.bus.queue.append((10.0003, message(cs.GetEncoderEstimates(n, 0.0, 0.0))))
    daemon.await_estimates()
    assert daemon.master.estimates_since(daemon.last_tick_at)
    assert daemon.clock_now == pytest.approx(10.0003)
    assert (daemon.stats.sensor_waits, daemon.stats.sensor_waits_in_vain) == (1, 0)
    # estimates later than the wait: the tick goes on with the ones it has after `sensor_wait`
    daemon.last_tick_at = daemon.clock_now
    daemon.master.bus.queue.append((daemon.clock_now + 0.0009, message(cs.GetEncoderEstimates(0, 0.0, 0.0))))
    start = daemon.clock_now
    daemon.await_estimates()
    assert daemon.clock_now - start == pytest.approx(daemon.config.sensor_wait)
    assert (daemon.stats.sensor_waits, daemon.stats.sensor_waits_in_vain) == (2, 1)


def test_no_wait_when_the_estimates_are_there_or_the_drives_send_slower_than_the_loop(daemon):
    running_with_drives_every(daemon, PERIOD)
    feed(daemon, 10.0, heartbeat=False)          # this period's set arrived before the tick
    daemon.await_estimates()
    assert daemon.stats.sensor_waits == 0 and daemon.clock_now == 10.0
    slow = ControllerDaemon(DaemonConfig(robot_id="unit", verbose=False, rate=1000.0),
                            *load("paper_convex").closed_loop("ce")[:2], MemoryBus(), MemorySession())
    slow.master.clock = lambda: slow.clock_now
    slow.clock_now = 10.0
    start(slow)
    running_with_drives_every(slow, 2 * slow.period)   # 500 Hz drives, 1 kHz loop: every other tick has none
    slow.await_estimates()
    assert slow.stats.sensor_waits == 0 and slow.clock_now == 10.0
    free = ControllerDaemon(DaemonConfig(robot_id="unit", verbose=False, sensor_sync=False),
                            *load("paper_convex").closed_loop("ce")[:2], MemoryBus(), MemorySession())
    free.master.clock = lambda: free.clock_now
    free.clock_now = 10.0
    start(free)
    running_with_drives_every(free, PERIOD)
    free.await_estimates()
    assert free.stats.sensor_waits == 0 and free.clock_now == 10.0


def test_sensor_to_torque_runs_from_the_oldest_estimate_used_to_the_torque_frames(daemon):
    import time

    arm(daemon)
    start = time.monotonic()
    feed(daemon, start - 0.0008, heartbeat=False)       # estimates that arrived 0.8 ms before the tick
    daemon.clock_now = start
    daemon.tick(start)
    stats = daemon.stats
    assert stats.sensor_to_torque.n == 1 and stats.torque_out.n == 1
    age = stats.sensor_to_torque.quantile(0.5)
    assert 0.0008 <= age <= 0.0008 + stats.torque_out.quantile(0.5) + 1e-5


def test_with_torque_at_the_torque_frames_leave_that_long_after_the_ticks_deadline(daemon):
    """Time-triggered output (--torque-at-us): computed at once, sent at deadline + torque_at, never before."""
    arm(daemon)
    daemon.master.bus.take()
    sent_at = []
    send = daemon.master.bus.send
    daemon.master.bus.send = lambda msg, timeout=None: (sent_at.append(time.monotonic()), send(msg, timeout))
    daemon.config.torque_at = 0.02
    daemon.deadline = time.monotonic()
    feed(daemon, 10.004, heartbeat=False)
    daemon.tick(10.004)
    assert len(sent_at) == 3 and min(sent_at) >= daemon.deadline + 0.02


def test_by_default_the_torques_leave_as_soon_as_computed():
    from sharedctl.services import cli

    assert DaemonConfig(robot_id="unit").torque_at == 0.0
    assert cli.build_parser().parse_args(["controller"]).torque_at_us == 0.0


def test_a_tick_reports_when_its_torques_were_ready_apart_from_when_they_left(daemon, monkeypatch):
    """The statistics' "torques ready" point comes before the output instant holds the frames, "torques sent"
    after they left: at the hold, the one is counted and the other not yet (no clock involved)."""
    from sharedctl.services.controller import daemon as daemon_module

    at_hold = []
    monkeypatch.setattr(daemon_module, "poll_until", lambda t: at_hold.append(
        (daemon.stats.torque_ready.n, daemon.stats.torque_out.n, t, len(daemon.master.bus.take()))))
    arm(daemon)
    daemon.config.torque_at = 0.02
    daemon.deadline = 10.002
    feed(daemon, 10.004, heartbeat=False)
    daemon.master.bus.take()
    daemon.tick(10.004)
    assert daemon.mode is Mode.RUNNING
    # ready counted, out not yet, nothing sent yet; the hold asked for deadline + torque_at
    assert at_hold == [(1, 0, pytest.approx(10.022), 0)]
    assert (daemon.stats.torque_ready.n, daemon.stats.torque_out.n) == (1, 1) and len(daemon.master.bus.take()) == 3


@pytest.mark.processes    # on the real clock: run alone, not beside the test workers
def test_the_loop_puts_a_busy_overrun_down_to_work_and_a_sleeping_one_to_not_running(daemon):
    """run() on the real clock: one tick busy for 10 ms, one asleep for 10 ms (5 periods each)."""
    class Stop:
        stopped = False

    daemon.master.clock = time.monotonic
    daemon.config.duration = 0.4
    tick, count = daemon.tick, [0]

    def stalling_tick(now):
        count[0] += 1
        if count[0] == 60:
            end = time.monotonic() + 0.01
            while time.monotonic() < end:
                pass
        if count[0] == 120:
            time.sleep(0.01)
        tick(now)

    causes = daemon.stats.miss_causes
    noted = {}                       # tick number → the cause its first miss was put down to
    note = causes.note

    def spying_note(n, *args, **kwargs):
        before = (causes.woke_late, causes.not_run, causes.working)
        note(n, *args, **kwargs)
        after = (causes.woke_late, causes.not_run, causes.working)
        if after != before:
            noted.setdefault(count[0],
                             ("woke_late", "not_run", "working")[[a > b for a, b in zip(after, before)].index(True)])

    causes.note = spying_note
    daemon.tick = stalling_tick
    summary = daemon.run(Stop())
    assert noted.get(60) == "working" and noted.get(120) == "not_run"
    assert summary["misses_working"] == causes.working and summary["missed"] + summary["late"] == (
        causes.woke_late + causes.not_run + causes.working)
    times = [m["t_s"] for m in summary["miss_times"]]
    assert {"working", "not running"} <= {m["cause"] for m in summary["miss_times"]}
    assert times == sorted(times) and 0.0 < times[0] < summary["elapsed_s"]


def test_the_frames_queued_before_the_clock_and_the_first_heartbeat_are_not_the_first_periods_work(daemon):
    """The frames that queued up while the daemon started, and the first put on the heartbeat publisher, are
    handled before the clock starts (`deadline` is None until the first tick) — not in the first period."""
    class Stop:
        stopped = False

    queued = [message(cs.Heartbeat(n % 3, ODriveError.NONE, AxisState.IDLE)) for n in range(40)]
    read_at, put_at = [], []      # the tick's deadline when each queued frame was read / each heartbeat put

    def recv(timeout=None):
        if not queued:
            return None
        read_at.append(daemon.deadline)
        return queued.pop(0)

    alive = daemon.links.alive_pub
    put = alive.put
    alive.put = lambda payload: (put_at.append(daemon.deadline), put(payload))
    daemon.master.bus.recv = recv
    daemon.master.clock = time.monotonic
    daemon.config.duration = 0.03
    before = daemon.master.rx_frames            # the start-up's frames (`start`)
    summary = daemon.run(Stop())
    assert summary["ticks"] > 0 and daemon.master.rx_frames == before + 40
    assert read_at == [None] * 40
    assert put_at == [None]                           # one heartbeat a second: the first went out before the clock


def test_the_loops_summary_holds_every_figure_the_bench_reports_and_is_strict_json(daemon, tmp_path):
    """run() on the real clock for 30 ms: its summary, written as the controller's `--json` file and read back by
    the bench (services/studies/bench/stack_run.py), has a value for every figure the bench reports."""
    from sharedctl.services.studies.bench.stack_run import DAEMON_KEYS, daemon_summary
    from sharedctl.services.summary_output import write_json

    class Stop:
        stopped = False

    daemon.master.clock = time.monotonic
    daemon.config.duration = 0.03
    before = daemon.master.rx_frames            # the start-up's frames (`start`)
    summary = daemon.run(Stop())
    write_json(tmp_path / "controller.json", summary)
    figures = daemon_summary(tmp_path / "controller.json")
    assert [key for key in DAEMON_KEYS if figures[key] is None] == []
    assert figures["ticks"] == summary["ticks"] > 0 and figures["frames_rx"] == before
    assert summary["mode"] == "starting"     # run() disarms first; no drive answers here
