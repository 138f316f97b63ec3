"""The controller's Prometheus collector (services/controller/metrics.py) on a real daemon stepped by hand
(in-memory bus and session), read back through prometheus_client's own exposition parser: every value is
one set or counted by hand here."""
from __future__ import annotations

import pytest
from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.parser import text_string_to_metric_families

from sharedctl.services.controller.loop_stats import LatenessHistogram
from sharedctl.services.controller.metrics import ControllerCollector
from sharedctl.services.lifecycle import RateClock

from .test_controller_loop import arm, feed, make_daemon, operator

P = "sharedctl_controller_"


def scrape(collector) -> dict:
    """{(sample name, frozenset(labels)): value} and {family name: type}, as a scraper parses the text."""
    registry = CollectorRegistry()
    registry.register(collector)
    samples, types = {}, {}
    for family in text_string_to_metric_families(generate_latest(registry).decode()):
        types[family.name] = family.type
        for s in family.samples:
            samples[(s.name, frozenset(s.labels.items()))] = s.value
    return samples, types


def value(samples, name, **labels):
    return samples[(name, frozenset(labels.items()))]


@pytest.fixture
def daemon():
    return make_daemon()


def test_loop_counters_and_the_achieved_rate_are_the_loops_own(daemon):
    daemon.stats.ticks, daemon.stats.late, daemon.stats.estops = 1234, 2, 3
    daemon.stats.torque_limited_ticks = 5
    daemon.stats.miss_causes.woke_late, daemon.stats.miss_causes.working = 4, 1
    daemon.clock = RateClock(0.002)
    daemon.clock.missed = 7
    daemon.stats.t0 = 100.0
    samples, types = scrape(ControllerCollector(daemon, "ce", now=lambda: 102.5))
    assert value(samples, P + "ticks_total") == 1234
    assert value(samples, P + "deadline_misses_total", kind="skipped") == 7
    assert value(samples, P + "deadline_misses_total", kind="late") == 2
    assert value(samples, P + "deadline_miss_causes_total", cause="woke_late") == 4
    assert value(samples, P + "deadline_miss_causes_total", cause="working") == 1
    assert value(samples, P + "estops_total") == 3
    assert value(samples, P + "torque_limited_ticks_total") == 5
    assert value(samples, P + "loop_rate_hertz") == 500.0
    assert value(samples, P + "loop_achieved_rate_hertz") == pytest.approx(1234 / 2.5)
    assert types[P + "ticks"] == "counter" and types[P + "loop_rate_hertz"] == "gauge"


def test_no_achieved_rate_before_the_loop_clock_starts(daemon):
    samples, _ = scrape(ControllerCollector(daemon, "ce"))
    assert not any(name == P + "loop_achieved_rate_hertz" for name, _ in samples)
    assert value(samples, P + "deadline_misses_total", kind="skipped") == 0


def test_the_jitter_histogram_has_cumulative_buckets_below_each_bound_and_the_sum(daemon):
    histogram = LatenessHistogram()
    durations = (3e-6, 15e-6, 15e-6, 0.7e-3, 0.06)       # the last beyond the histogram's 50 ms
    for duration in durations:
        histogram.add(duration)
    daemon.stats.jitter = histogram
    samples, types = scrape(ControllerCollector(daemon, "ce"))
    expected = {"1e-05": 1, "2e-05": 3, "5e-05": 3, "0.0001": 3, "0.0005": 3, "0.001": 4, "0.05": 4, "+Inf": 5}
    for le, count in expected.items():
        assert value(samples, P + "jitter_seconds_bucket", le=le) == count, le
    assert value(samples, P + "jitter_seconds_count") == 5
    assert value(samples, P + "jitter_seconds_sum") == pytest.approx(sum(durations))
    assert types[P + "jitter_seconds"] == "histogram"


def test_feedback_age_and_the_can_round_trip_once_measured(daemon):
    arm(daemon)                                  # estimates at 10.001, tick at 10.002
    samples, _ = scrape(ControllerCollector(daemon, "ce"))
    assert value(samples, P + "feedback_age_seconds") == pytest.approx(0.001)
    assert not any(name == P + "can_round_trip_seconds" for name, _ in samples)   # none measured yet
    daemon.master.probe.probe_sent(1, 10.0)
    daemon.master.probe.reply(1, 10.0004)
    samples, _ = scrape(ControllerCollector(daemon, "ce"))
    assert value(samples, P + "can_round_trip_seconds") == pytest.approx(0.0004)
    assert value(samples, P + "can_round_trip_probes_total", outcome="replied") == 1


def test_the_lease_holder_appears_after_a_command_and_rejections_are_counted_by_reason(daemon):
    arm(daemon)
    samples, _ = scrape(ControllerCollector(daemon, "ce"))
    assert value(samples, P + "lease_held") == 0
    assert value(samples, P + "operator_hands_off") == 1                # no command yet
    assert not any(name == P + "lease_holder_info" for name, _ in samples)
    operator(daemon, 1, 10.003)
    operator(daemon, 1, 10.004)                 # the same seq again: a replay
    operator(daemon, 1, 10.004)
    feed(daemon, 10.005, heartbeat=False)
    daemon.tick(10.005)
    samples, _ = scrape(ControllerCollector(daemon, "ce"))
    assert value(samples, P + "lease_held") == 1
    assert value(samples, P + "lease_holder_info", operator="op") == 1
    assert value(samples, P + "lease_grants_total") == 1
    assert value(samples, P + "operator_hands_off") == 0                # the holder's command drives
    assert value(samples, P + "operator_commands_accepted_total") == 1
    assert value(samples, P + "rejected_messages_total", reason="duplicate_seq") == 2
    daemon.policy.offer(b"\xc1 not msgpack", 10.006)
    daemon.tick(10.006)
    samples, _ = scrape(ControllerCollector(daemon, "ce"))
    assert value(samples, P + "operator_hands_off") == 1                # a malformed payload: hands-off
    rejected = {dict(labels)["reason"]: v for (name, labels), v in samples.items()
                if name == P + "rejected_messages_total"}
    assert sum(rejected.values()) == 3 and len(rejected) == 2        # and the undecodable payload, by its error


def test_an_operator_estop_counts_and_shows_the_mode(daemon):
    arm(daemon)
    operator(daemon, 1, 10.003, estop=True)
    feed(daemon, 10.004, heartbeat=False)
    daemon.tick(10.004)
    samples, _ = scrape(ControllerCollector(daemon, "ce"))
    assert value(samples, P + "estops_total") == 1
    assert value(samples, P + "mode", mode="estopped") == 1
    assert value(samples, P + "mode", mode="running") == 0
