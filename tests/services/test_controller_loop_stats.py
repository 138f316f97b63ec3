"""The loop's observer (services/controller/loop_stats.py) on a hand-driven clock: what each point records and
the summary it builds, units in the key names. The oracle is hand arithmetic: a duration counts in its 10 µs bin,
a quantile is that bin's upper edge."""
from types import SimpleNamespace

import pytest

from sharedctl.services.controller import loop_stats
from sharedctl.services.controller.loop_stats import LoopStats

PERIOD = 0.002


class FakeTime:
    """`time.monotonic`, `time.thread_time` and `time.process_time`, set by hand."""

    def __init__(self):
        self.now, self.thread, self.process = 100.0, 0.0, 0.0

    def monotonic(self):
        return self.now

    def thread_time(self):
        return self.thread

    def process_time(self):
        return self.process


@pytest.fixture
def clock(monkeypatch):
    fake = FakeTime()
    monkeypatch.setattr(loop_stats, "time", fake)
    return fake


def observer(torque_at=0.0):
    frames, commands = SimpleNamespace(rx_frames=0), SimpleNamespace(taken=0)
    return LoopStats(PERIOD, torque_at, frames=frames, commands=commands), frames, commands


def test_a_ticks_durations_are_reported_in_microseconds(clock):
    stats, _, _ = observer()
    stats.start()
    stats.period_start(0.000045, 0, True, 100.0)            # 45 µs late: the 40–50 µs bin
    start = clock.now = 100.001
    clock.now = start + 0.000145
    stats.torques_ready(start)
    clock.now = start + 0.000205
    stats.torques_sent(start, feedback_age=0.0008)           # 205 µs out; 1005 µs after the oldest estimate
    clock.now = start + 0.000405
    stats.tick_done(start)
    summary = stats.summary(missed=0)
    assert (summary["jitter_p50_us"], summary["jitter_max_us"]) == (50.0, 45.0)
    assert (summary["torque_ready_p50_us"], summary["torque_out_p50_us"], summary["compute_p50_us"]) == (
        150.0, 210.0, 410.0)
    assert summary["sensor_to_torque_p50_us"] == 1010.0
    assert summary["ticks"] == 1 and summary["late"] == 0


def test_the_loop_threads_cpu_per_period_runs_from_the_tick_start_to_the_end_of_the_reading(clock):
    stats, _, _ = observer()
    stats.start()
    for k, cpu in enumerate((0.000425, 0.000615, 0.000435)):
        clock.thread = 10.0 * k
        stats.period_start(0.0, 0, True, clock.now)
        clock.thread += cpu
        stats.period_end()
    summary = stats.summary(missed=0)
    assert (summary["loop_cpu_p50_us"], summary["loop_cpu_p99_us"]) == (440.0, 620.0)


def test_a_deadline_missed_after_a_busy_period_is_put_down_to_work_with_the_work_and_time_of_that_period(clock):
    stats, frames, commands = observer()
    stats.start()                                            # t0 = 100.0
    stats.period_start(0.0, 0, True, 100.0)
    stats.tick_done(100.0)
    clock.thread = 0.0005
    stats.period_end()                                       # an ordinary period: 0.5 ms of thread CPU
    clock.thread = 1.0
    stats.period_start(0.0, 0, True, 100.002)
    stats.tick_done(100.002)
    clock.thread, frames.rx_frames, commands.taken = 1.003, 7, 1
    stats.period_end()                                       # a busy one: 3 ms, 7 frames, 1 operator message
    stats.period_start(0.0012, 1, False, 100.005)            # one deadline skipped and this one 1.2 ms late
    summary = stats.summary(missed=1)
    assert (summary["missed"], summary["late"], summary["misses_working"], summary["misses_not_run"]) == (1, 1, 2, 0)
    assert summary["misses_working_cpu_p50_us"] == 3000.0
    assert (summary["misses_working_frames_p50"], summary["misses_working_commands_p50"]) == (7.0, 1.0)
    assert summary["miss_times"] == [{"t_s": 0.005, "cause": "working"}]


def test_the_first_periods_miss_has_no_period_before_it_to_blame(clock):
    stats, _, _ = observer()
    stats.start()
    stats.period_start(0.003, 1, False, 100.0)
    summary = stats.summary(missed=1)
    assert summary["late"] == 1 and summary["miss_times"] == []
    assert summary["misses_woke_late"] + summary["misses_not_run"] + summary["misses_working"] == 0


def test_waits_for_the_estimates_estops_and_torque_limited_ticks_are_counted(clock):
    stats, _, _ = observer()
    for arrived in (True, False, True):
        stats.sensor_wait(arrived)
    stats.estop()
    stats.torque_limited()
    stats.torque_limited()
    summary = stats.summary(missed=0)
    assert (summary["sensor_waits"], summary["sensor_waits_in_vain"]) == (3, 1)
    assert (summary["estops"], summary["torque_limited_ticks"]) == (1, 2)


def test_rate_and_cpu_are_over_the_time_since_the_clock_started_with_the_process_counts_beside_them(clock):
    stats, _, _ = observer(torque_at=0.00035)
    stats.start()
    for _ in range(10):
        stats.tick_done(clock.now)
    clock.now, clock.process = 102.0, 0.5
    summary = stats.summary(missed=0, counts={"frames_rx": 12, "rejections": {"stale": 2}, "mode": "running"})
    assert (summary["elapsed_s"], summary["rate_hz"], summary["cpu_percent"]) == (2.0, 5.0, 25.0)
    assert summary["torque_at_us"] == 350.0
    assert (summary["frames_rx"], summary["rejections"], summary["mode"]) == (12, {"stale": 2}, "running")
