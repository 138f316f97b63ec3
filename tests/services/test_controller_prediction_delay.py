"""The delay the daemon (services/controller/daemon.py) passes to `SharedController.step`: the oldest wheel
estimate's age + the measured CAN round trip (+ the hold with `torque_at`), cut to 100 ms; 0 with --no-predict.
Stepped by hand on an injected clock; the step is recorded as called."""
import time

import can
import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.services.controller.daemon import ControllerDaemon, DaemonConfig, Mode
from sharedctl.services.scenario_files import load

from .test_controller_loop import MemoryBus, MemorySession, arm, feed, make_daemon


def message(frame):
    f = cs.encode(frame)
    return can.Message(arbitration_id=f.arbitration_id, data=f.data, dlc=f.dlc, is_extended_id=False)


@pytest.fixture
def daemon(monkeypatch):
    d = make_daemon()
    d.delays, d.intervals = [], []
    step = d.controller.step

    def recording_step(state, q, v, operator, dt, delay=0.0, elapsed=None):
        d.delays.append(delay)
        d.intervals.append((dt, elapsed))
        return step(state, q, v, operator, dt, delay, elapsed)

    monkeypatch.setattr(d.controller, "step", recording_step)
    return d


def measure_round_trip(d, seconds):
    """One poll answered `seconds` later, on the master's clock (the daemon's `clock_now`)."""
    assert d.master.probe_round_trip()
    node = d.master.bus.sent[-1].node_id
    d.master.handle(message(cs.GetBusVoltageCurrent(node, 24.0, 0.0)), d.clock_now + seconds)


def test_the_delay_is_the_feedback_age_alone_until_the_round_trip_is_measured(daemon):
    arm(daemon)
    feed(daemon, 10.0030, heartbeat=False)
    daemon.tick(10.0042)
    assert daemon.mode is Mode.RUNNING
    assert daemon.delays[-1] == pytest.approx(0.0012, abs=1e-12)


def test_the_delay_is_the_feedback_age_plus_the_measured_round_trip(daemon):
    arm(daemon)
    measure_round_trip(daemon, 0.006)
    feed(daemon, 10.0030, heartbeat=False)
    daemon.tick(10.0042)
    assert daemon.delays[-1] == pytest.approx(0.0012 + 0.006, abs=1e-12)


def test_the_round_trip_used_is_the_largest_measured_recently(daemon):
    arm(daemon)
    for seconds in (0.004, 0.009, 0.002):
        daemon.master.probe.schedule.next = daemon.clock_now      # the next poll due at once
        measure_round_trip(daemon, seconds)
    feed(daemon, 10.0030, heartbeat=False)
    daemon.tick(10.0030)
    assert daemon.delays[-1] == pytest.approx(0.009, abs=1e-12)


def test_with_torque_at_the_hold_until_the_torques_leave_is_added(daemon, monkeypatch):
    from sharedctl.services.controller import daemon as daemon_module

    monkeypatch.setattr(daemon_module, "poll_until", lambda t: None)
    arm(daemon)
    measure_round_trip(daemon, 0.003)
    daemon.config.torque_at = 0.001
    daemon.deadline = 10.0040                                     # torques leave at 10.0050
    feed(daemon, 10.0035, heartbeat=False)
    daemon.tick(10.0041)
    assert daemon.delays[-1] == pytest.approx(0.0006 + 0.003 + 0.0009, abs=1e-12)


def test_a_late_tick_gives_the_predictor_the_time_the_last_command_acted_and_the_laws_at_most_four_periods(daemon):
    """A tick 12 ms after the last one (a stalled host): the torques of the last tick acted those 12 ms, and the
    step's predictor must run them that long (shared_controller.in_flight); the laws' own integration stays cut
    to four periods."""
    arm(daemon)
    for now in (10.004, 10.006, 10.018, 10.020, 10.080):
        feed(daemon, now - 0.0005, heartbeat=False)
        daemon.tick(now)
    assert daemon.mode is Mode.RUNNING
    steps = daemon.intervals[-5:]
    assert steps[1] == (pytest.approx(0.002), pytest.approx(0.002))
    assert steps[2] == (pytest.approx(0.008), pytest.approx(0.012))
    assert steps[3] == (pytest.approx(0.002), pytest.approx(0.002))
    assert steps[4] == (pytest.approx(0.008), pytest.approx(0.060))
    assert daemon.state.held[-4:] == pytest.approx((0.002, 0.012, 0.002, 0.060))


def test_the_delay_is_cut_to_100_ms(daemon):
    arm(daemon)
    measure_round_trip(daemon, 0.150)
    feed(daemon, 10.0030, heartbeat=False)
    daemon.tick(10.0042)
    assert daemon.delays[-1] == 0.1


def test_at_1_khz_the_delay_is_cut_to_the_64_periods_of_commands_the_predictor_keeps():
    loop, q0, _ = load("paper_convex").closed_loop("ce")
    d = ControllerDaemon(DaemonConfig(robot_id="unit", verbose=False, rate=1000.0), loop, q0, MemoryBus(),
                         MemorySession())
    assert d.max_delay == pytest.approx(0.064)
    d.master.clock = lambda: 10.0
    assert d.master.probe_round_trip()
    d.master.handle(message(cs.GetBusVoltageCurrent(0, 24.0, 0.0)), 10.080)
    d.feedback_age = 0.010
    assert d.prediction_delay(10.0) == pytest.approx(0.064)


def test_without_prediction_the_step_gets_no_delay(daemon):
    daemon.config.predict = False
    arm(daemon)
    measure_round_trip(daemon, 0.006)
    feed(daemon, 10.0030, heartbeat=False)
    daemon.tick(10.0042)
    assert daemon.delays and set(daemon.delays) == {0.0}


def test_prediction_is_on_and_polls_go_out_at_10_hz_by_default():
    from sharedctl.services import cli

    config = DaemonConfig(robot_id="unit")
    args = cli.build_parser().parse_args(["controller"])
    assert (config.predict, config.rtt_probe_rate, args.predict, args.rtt_probe_rate) == (True, 10.0, True, 10.0)
    assert cli.build_parser().parse_args(["controller", "--no-predict"]).predict is False


@pytest.mark.parametrize("rate", ["-1", "51", "nan"])
def test_a_probe_rate_outside_0_to_50_hz_is_refused_before_anything_starts(rate, capsys, monkeypatch):
    from sharedctl.services import cli
    from sharedctl.services.lifecycle import StopFlag

    monkeypatch.setattr(StopFlag, "install", lambda self: self)     # the test process keeps its signal handlers
    args = cli.build_parser().parse_args(["controller", "--rtt-probe-rate", rate])
    assert args.handler(args) == 2
    assert "--rtt-probe-rate" in capsys.readouterr().err


class AnsweringBus(MemoryBus):
    """The drives on the bus answer every Get_Bus_Voltage_Current poll at once (the reply stamped when sent)."""

    def __init__(self):
        super().__init__()
        self.replies = []

    def send(self, msg, timeout=None):
        super().send(msg, timeout)
        if msg.is_remote_frame:
            f = cs.encode(cs.GetBusVoltageCurrent(msg.arbitration_id >> 5, 24.0, 0.0))
            self.replies.append(can.Message(arbitration_id=f.arbitration_id, data=f.data, dlc=f.dlc,
                                            is_extended_id=False, timestamp=time.time()))

    def recv(self, timeout=None):
        return self.replies.pop(0) if self.replies else None


def test_the_loops_summary_reports_the_round_trip_and_the_poll_counts(tmp_path):
    """run() on the real clock for 30 ms against drives that answer: the poll went out, its reply was read with the
    other frames, and the summary (strict JSON, as `--json` writes it) holds the round trip and the counters."""
    from sharedctl.services.summary_output import read_json, write_json

    class Stop:
        stopped = False

    loop, q0, _ = load("paper_convex").closed_loop("ce")
    d = ControllerDaemon(DaemonConfig(robot_id="unit", verbose=False, duration=0.03), loop, q0, AnsweringBus(),
                         MemorySession())
    write_json(tmp_path / "controller.json", d.run(Stop()))
    summary = read_json(tmp_path / "controller.json")
    probes = summary["rtt_probes"]
    assert probes["sent"] >= 1 and probes["replies"] >= 1 and probes["timeouts"] == 0
    assert 0.0 <= summary["can_round_trip_ms"] <= 200.0          # a reply counts only within the 0.2 s timeout
    unanswered = ControllerDaemon(DaemonConfig(robot_id="unit", verbose=False, duration=0.03), loop, q0, MemoryBus(),
                                  MemorySession())
    write_json(tmp_path / "silent.json", unanswered.run(Stop()))
    silent = read_json(tmp_path / "silent.json")
    assert silent["can_round_trip_ms"] is None and silent["rtt_probes"]["sent"] >= 1
