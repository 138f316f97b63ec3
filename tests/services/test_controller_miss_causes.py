"""MissCauses (services/controller/loop_stats.py): a missed or late deadline is put down to the machine
(the loop woke late, or its period overran without using the CPU for it) or to work (it used the CPU)."""
from sharedctl.services.controller.loop_stats import LoopStats, MissCauses

MEDIAN = 0.0006    # s of thread CPU per period, the loop's median


def test_a_loop_that_reached_its_clock_in_time_and_woke_late_was_not_run():
    causes = MissCauses()
    causes.note(1, reached_clock_in_time=True, period_cpu=5 * MEDIAN, median_cpu=MEDIAN)
    assert (causes.woke_late, causes.not_run, causes.working) == (1, 0, 0)


def test_an_overrun_that_used_little_cpu_was_the_thread_not_running():
    causes = MissCauses()
    causes.note(3, reached_clock_in_time=False, period_cpu=1.5 * MEDIAN, median_cpu=MEDIAN)
    assert (causes.woke_late, causes.not_run, causes.working) == (0, 3, 0)


def test_an_overrun_that_used_over_twice_the_median_cpu_was_work():
    causes = MissCauses()
    causes.note(2, reached_clock_in_time=False, period_cpu=0.004, median_cpu=MEDIAN, work=(7, 1))
    causes.note(1, reached_clock_in_time=False, period_cpu=0.002, median_cpu=MEDIAN, work=(9, 3))
    assert (causes.woke_late, causes.not_run, causes.working) == (0, 0, 3)
    assert causes.working_cpu_p50() == 0.003 and causes.working_work_p50() == (8.0, 2.0)


def test_ticks_on_time_are_not_counted():
    causes = MissCauses()
    causes.note(0, reached_clock_in_time=False, period_cpu=1.0, median_cpu=MEDIAN)
    assert (causes.woke_late, causes.not_run, causes.working, causes.working_cpu_p50()) == (0, 0, 0, 0.0)
    assert causes.working_work_p50() == (0.0, 0.0)


def test_the_summary_reports_every_cause_with_the_work_of_the_overruns():
    stats = LoopStats(0.002)
    stats.miss_causes.note(5, reached_clock_in_time=True, period_cpu=MEDIAN, median_cpu=MEDIAN)
    stats.miss_causes.note(6, reached_clock_in_time=False, period_cpu=MEDIAN, median_cpu=MEDIAN)
    stats.miss_causes.note(7, reached_clock_in_time=False, period_cpu=0.0015, median_cpu=MEDIAN, work=(9, 2))
    summary = stats.summary(missed=0)
    assert (summary["misses_woke_late"], summary["misses_not_run"], summary["misses_working"]) == (5, 6, 7)
    assert summary["misses_working_cpu_p50_us"] == 1500.0
    assert (summary["misses_working_frames_p50"], summary["misses_working_commands_p50"]) == (9.0, 2.0)


def test_the_first_misses_are_kept_with_their_time_and_cause_and_only_the_first():
    causes = MissCauses()
    causes.note(1, reached_clock_in_time=False, period_cpu=0.004, median_cpu=MEDIAN, at=0.3125)
    causes.note(2, reached_clock_in_time=True, period_cpu=MEDIAN, median_cpu=MEDIAN, at=4.5)
    causes.note(1, reached_clock_in_time=False, period_cpu=MEDIAN, median_cpu=MEDIAN, at=7.25)
    causes.note(0, reached_clock_in_time=False, period_cpu=1.0, median_cpu=MEDIAN, at=8.0)     # on time: not kept
    assert causes.times == [(0.3125, "working"), (4.5, "woke late"), (7.25, "not running")]
    for k in range(2 * MissCauses.KEEP):
        causes.note(1, reached_clock_in_time=True, period_cpu=MEDIAN, median_cpu=MEDIAN, at=10.0 + k)
    assert len(causes.times) == MissCauses.KEEP and causes.times[-1] == (10.0 + MissCauses.KEEP - 4, "woke late")


def test_the_summary_lists_the_first_misses_with_their_time_and_cause():
    stats = LoopStats(0.002)
    assert stats.summary(missed=0)["miss_times"] == []
    stats.miss_causes.note(1, reached_clock_in_time=False, period_cpu=0.004, median_cpu=MEDIAN, at=0.3125)
    stats.miss_causes.note(2, reached_clock_in_time=True, period_cpu=MEDIAN, median_cpu=MEDIAN, at=4.5)
    assert stats.summary(missed=0)["miss_times"] == [{"t_s": 0.3125, "cause": "working"},
                                                     {"t_s": 4.5, "cause": "woke late"}]
