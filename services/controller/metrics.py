"""The controller's Prometheus metrics (`sharedctl controller --metrics HOST:PORT`; docs/metrics.md).

`ControllerCollector.collect()` runs on the metrics server's thread at each scrape and reads what the
daemon already counts — its loop statistics (loop_stats.py), its clock, its CAN master (can_master.py,
round_trip.py), the operator input policy (operator_input.py, lease.py) and the last tick's feedback
age and operator status. Nothing is measured for it and nothing is added to the tick. It takes no lock
(the loop thread is real-time: a lock held by this thread while it is preempted would stall the loop):
each figure is one attribute read; a counter dict is copied whole in one C call under the GIL; a
histogram's bins are copied and their count taken from the copy, so its buckets agree with each other.
A figure the daemon has not got yet (no tick, no round trip measured) is left out rather than made up.

The loop's histograms (`LatenessHistogram`: 10 µs bins over the whole run) become Prometheus
histograms on the fixed bounds `BUCKETS`, each bucket counting the durations *below* its bound.
"""
from __future__ import annotations

import math
import time

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily, InfoMetricFamily
from prometheus_client.utils import floatToGoString

from ..metrics import unit_of
from .daemon import Mode

PREFIX = "sharedctl_controller_"
BUCKETS = (1e-5, 2e-5, 5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2)   # s, multiples of the 10 µs bin

HISTOGRAMS = (   # (LoopStats attribute, metric name, help)
    ("jitter", "jitter_seconds", "Each tick's lateness after its deadline (the clock's wake-up)."),
    ("compute", "compute_seconds", "Each tick's work, from its start to its control and telemetry done."),
    ("torque_out", "torque_out_seconds", "Each tick's start to its torque frames handed to the bus."),
    ("sensor_to_torque", "sensor_to_torque_seconds",
     "Arrival of the oldest wheel estimate a tick used to its torque frames sent."),
    ("loop_cpu", "loop_cpu_seconds", "The loop thread's CPU time per period, outside the clock's wait."),
)


def histogram_buckets(histogram, bounds=BUCKETS) -> tuple[list[tuple[str, float]], float]:
    """A `LatenessHistogram` as cumulative Prometheus buckets on `bounds` (s, multiples of its bin) and +Inf,
    with its sum (s). Bucket `le=b` counts the durations below b."""
    counts = histogram.counts.copy()          # one consistent copy: the loop keeps adding
    total = histogram.total
    cumulative = counts.cumsum()
    buckets = [(floatToGoString(b), float(cumulative[min(round(b / histogram.BIN) - 1, histogram.last)]))
               for b in bounds]
    buckets.append(("+Inf", float(cumulative[-1])))
    return buckets, total


def _counter(name: str, documentation: str, value: float) -> CounterMetricFamily:
    return CounterMetricFamily(PREFIX + name, documentation, value=value, unit=unit_of(name))


def _gauge(name: str, documentation: str, value: float | None = None, labels=None) -> GaugeMetricFamily:
    return GaugeMetricFamily(PREFIX + name, documentation, value=value, labels=labels, unit=unit_of(name))


def _labelled_counter(name: str, documentation: str, label: str, values: dict) -> CounterMetricFamily:
    family = CounterMetricFamily(PREFIX + name, documentation, labels=[label], unit=unit_of(name))
    for key, value in sorted(values.items()):
        family.add_metric([str(key)], value)
    return family


class ControllerCollector:
    """Reads `daemon` (a `ControllerDaemon`) at each scrape: see the module doc and docs/metrics.md."""

    def __init__(self, daemon, law: str = "", now=time.monotonic) -> None:
        self.daemon, self.law, self.now = daemon, law, now

    def collect(self):
        d = self.daemon
        stats, master, policy, config = d.stats, d.master, d.policy, d.config
        yield InfoMetricFamily(PREFIX.rstrip("_"), "The controller's robot, scenario, machine law and lease mode.",
                               value={"robot_id": config.robot_id, "scenario": config.scenario, "law": self.law,
                                      "lease_mode": str(policy.lease.mode)})
        mode = d.mode
        family = _gauge("mode", "1 for the mode the controller is in, 0 for the others.", labels=["mode"])
        for m in Mode:
            family.add_metric([m.value], 1.0 if m is mode else 0.0)
        yield family

        # --- the loop
        yield _gauge("loop_rate_hertz", "The configured control loop rate.", config.rate)
        clock, t0 = d.clock, stats.t0
        if clock is not None and t0 > 0.0 and (elapsed := self.now() - t0) > 0.0:
            yield _gauge("loop_achieved_rate_hertz", "Ticks per second since the loop's clock started.",
                         stats.ticks / elapsed)
        yield _counter("ticks_total", "Control periods ticked (read, step, write, telemetry).", stats.ticks)
        misses = _labelled_counter(
            "deadline_misses_total", "Deadlines missed: skipped by the clock (no tick), or ticked more than half a "
            "period late.", "kind", {"skipped": clock.missed if clock is not None else 0, "late": stats.late})
        yield misses
        causes = stats.miss_causes
        yield _labelled_counter("deadline_miss_causes_total", "Missed and late deadlines by cause (loop_stats.py).",
                                "cause", {"woke_late": causes.woke_late, "not_running": causes.not_run,
                                          "working": causes.working})
        yield _counter("estops_total", "Emergency stops the loop sent (every cause).", stats.estops)
        yield _counter("torque_limited_ticks_total", "Ticks whose wheel torques were scaled down to the limit.",
                       stats.torque_limited_ticks)
        yield _labelled_counter("sensor_waits_total", "Ticks that waited for their period's wheel estimates, by "
                                "whether they arrived.", "outcome",
                                {"arrived": stats.sensor_waits - stats.sensor_waits_in_vain,
                                 "in_vain": stats.sensor_waits_in_vain})
        for attribute, name, documentation in HISTOGRAMS:
            buckets, total = histogram_buckets(getattr(stats, attribute))
            yield HistogramMetricFamily(PREFIX + name, documentation, buckets=buckets, sum_value=total,
                                        unit=unit_of(name))

        # --- CAN
        age = d.feedback_age
        yield _gauge("feedback_age_seconds", "Age of the oldest wheel estimate at the last tick's start (+Inf "
                     "before every wheel has reported).", age)
        yield _counter("can_frames_received_total", "CAN frames read (every id).", master.rx_frames)
        yield _counter("can_frames_sent_total", "CAN frames sent.", master.tx_frames)
        yield _labelled_counter("can_bad_frames_total", "CAN frames the codec refused, by error.", "error",
                                dict(master.bad_frames))
        yield _labelled_counter("can_implausible_estimates_total", "Wheel encoder values replaced as implausible, "
                                "by reason (encoder_check.py).", "reason", dict(master.implausible_estimates))
        yield _counter("can_foreign_commands_total", "Drive commands on the bus this controller did not send "
                       "(another CAN master).", master.foreign_commands)
        probe = master.probe
        round_trip = probe.round_trip
        if math.isfinite(round_trip):
            yield _gauge("can_round_trip_seconds", "The CAN round trip: the largest of the last measured polls "
                         "(round_trip.py).", round_trip)
        yield _labelled_counter("can_round_trip_probes_total", "Round-trip polls by outcome: sent, replied "
                                "(measured), timed_out, unmatched replies.", "outcome",
                                {"sent": probe.sent, "replied": probe.replies, "timed_out": probe.timeouts,
                                 "unmatched": probe.unmatched})

        # --- operators
        yield _counter("operator_commands_accepted_total", "Operator commands accepted.", policy.accepted)
        yield _labelled_counter("rejected_messages_total", "Operator commands and lease requests refused, by "
                                "reason.", "reason", dict(policy.rejections))
        status = d.status
        if status is not None:
            yield _gauge("operator_link_latency_seconds", "Receive time minus send time of the last accepted "
                         "command (0 when unknown).", status.latency)
            yield _gauge("operator_link_loss_ratio", "Sequence gaps over the last 200 commands of the current "
                         "session.", status.loss_fraction)
            yield _gauge("operator_staleness_seconds", "Time since the last accepted command (+Inf before any), "
                         "at the last tick.", status.staleness)
            yield _gauge("operator_hands_off", "1 while the operator input is hands-off (u_h = 0).",
                         1.0 if status.hands_off else 0.0)
        holder, lease = d.lease_holder, policy.lease
        yield _gauge("lease_held", "1 while an operator holds the control lease.", 0.0 if holder is None else 1.0)
        family = InfoMetricFamily(PREFIX + "lease_holder", "The operator holding the control lease (no sample "
                                  "while it is free).", labels=["operator"])
        if holder is not None:
            family.add_metric([holder], {})
        yield family
        yield _counter("lease_grants_total", "Control leases granted (a renewal is not a grant).",
                       lease.grants)
        yield _counter("lease_expirations_total", "Control leases that expired without renewal.", lease.expirations)
