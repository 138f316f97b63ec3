"""The simulated robot's Prometheus metrics (`sharedctl robot --metrics HOST:PORT`; docs/metrics.md).

`RobotCollector.collect()` runs on the metrics server's thread at each scrape and reads what the
process already counts: its loop clock's missed ticks, its frame counters (process.py), the
simulation's steps and skipped time, and each axis's state, watchdog trips and restarts
(simulation.py, axis.py). One attribute read per figure, the frame counters copied whole in one C
call under the GIL; nothing is added to the physics loop.
"""
from __future__ import annotations

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, InfoMetricFamily

from ..metrics import unit_of

PREFIX = "sharedctl_robot_"
IGNORED = {"echo": "echoes", "other_node": "other_nodes", "error_frame": "error_frames"}   # label → count key


def _counter(name: str, documentation: str, value: float | None = None, labels=None) -> CounterMetricFamily:
    return CounterMetricFamily(PREFIX + name, documentation, value=value, labels=labels, unit=unit_of(name))


def _gauge(name: str, documentation: str, value: float | None = None, labels=None) -> GaugeMetricFamily:
    return GaugeMetricFamily(PREFIX + name, documentation, value=value, labels=labels, unit=unit_of(name))


def _per_axis(family, axes, value):
    for axis in axes:
        family.add_metric([str(axis.node_id)], value(axis))
    return family


class RobotCollector:
    """Reads `process` (a `RobotProcess`) at each scrape: see the module doc and docs/metrics.md."""

    def __init__(self, process) -> None:
        self.process = process

    def collect(self):
        process = self.process
        sim = process.sim
        config = sim.config
        counts = dict(process.counts)
        axes = list(sim.axes)
        clock = process.clock
        yield InfoMetricFamily(PREFIX.rstrip("_"), "The simulated robot's id.", value={"robot_id": process.robot_id})
        yield _gauge("physics_rate_hertz", "The configured physics rate.", config.physics_rate_hz)
        yield _counter("physics_steps_total", "RK4 physics steps taken.", sim.steps)
        yield _gauge("simulated_seconds", "The simulation's time since start.", sim.time)
        yield _counter("skipped_seconds_total", "Simulated time skipped after stalls longer than the catch-up "
                       "limit (50 steps).", sim.skipped_time)
        yield _counter("missed_ticks_total", "Physics-loop deadlines the clock skipped (overruns).",
                       clock.missed if clock is not None else 0)
        yield _counter("can_frames_received_total", "Host → drive CAN frames decoded.", counts.get("frames_in", 0))
        yield _counter("can_frames_sent_total", "Drive → host CAN frames sent.", counts.get("frames_out", 0))
        ignored = _counter("can_frames_ignored_total", "CAN frames skipped before decoding, by reason: the robot's "
                           "own echoes, frames for other nodes, error frames.", labels=["reason"])
        for label, key in IGNORED.items():
            ignored.add_metric([label], counts.get(key, 0))
        yield ignored
        yield _counter("can_decode_errors_total", "CAN frames unreadable or refused by the CANSimple codec.",
                       counts.get("bad_frames", 0))
        yield _counter("can_send_errors_total", "CAN frames that could not be sent.", counts.get("send_errors", 0))
        yield _counter("truth_messages_total", "GroundTruth messages published.", process.truth_seq)
        yield _per_axis(_gauge("axis_armed", "1 while the axis is in closed-loop control.", labels=["axis"]),
                        axes, lambda axis: 1.0 if axis.armed else 0.0)
        braked = config.brake_torque > 0.0
        yield _per_axis(_gauge("brake_engaged", "1 while the wheel's fail-safe brake holds it (its drive disarmed, "
                               "the robot has brakes).", labels=["axis"]),
                        axes, lambda axis: 1.0 if braked and not axis.armed else 0.0)
        yield _per_axis(_counter("watchdog_trips_total", "Drive watchdog expiries (axis disarmed).", labels=["axis"]),
                        axes, lambda axis: axis.watchdog_trips)
        yield _per_axis(_counter("drive_restarts_total", "Drive restarts (power loss and reboot).", labels=["axis"]),
                        axes, lambda axis: axis.restarts)
