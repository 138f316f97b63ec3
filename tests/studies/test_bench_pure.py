"""The pure parts of `sharedctl bench`: bus-load arithmetic, statistics, and the analysis of a bus capture."""
from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

from sharedctl.protocol.odrive_enums import CommandId
from sharedctl.services.studies.bench.bus_load import bus_load, frame_bits
from sharedctl.services.studies.bench.command import check_targets, finite_or_null
from sharedctl.services.studies.bench.stack_run import Frame, analyse, analyse_turns
from sharedctl.services.studies.bench.statistics import group_bursts, missed_periods, percentiles, period_jitter


def controller_json(tmp_path, **figures):
    """A controller's `--json` exit summary (services/controller/loop_stats.py's names), as a file."""
    path = tmp_path / "controller.json"
    path.write_text(json.dumps({"ticks": 10, "missed": 0, "late": 0, "miss_times": [], **figures}))
    return path


def test_worst_case_frame_lengths_with_bit_stuffing():
    assert frame_bits(8) == 135        # 34 + 64 + 13 + ⌊97/4⌋
    assert frame_bits(4) == 95
    assert frame_bits(0) == 55


def test_a_remote_frame_has_no_data_field_whatever_its_dlc():
    assert frame_bits(8, is_remote=True) == frame_bits(0)


def test_extended_identifiers_cost_more():
    assert frame_bits(8, is_extended=True) == 160


def test_dlc_outside_classic_can_is_refused():
    with pytest.raises(ValueError):
        frame_bits(9)


def test_bus_load_of_the_default_rates():
    # 3 axes × 500 Hz encoder estimates (8 bytes) + 3 × 500 Hz torque commands (4 bytes)
    # + 3 × 10 Hz heartbeats (8 bytes)
    frames = [(8, False, False)] * 1500 + [(4, False, False)] * 1500 + [(8, False, False)] * 30
    assert bus_load(frames, 1.0) == pytest.approx((1530 * 135 + 1500 * 95) / 1e6)
    assert bus_load(frames, 2.0) == pytest.approx(bus_load(frames, 1.0) / 2)


def test_percentiles_and_empty_samples():
    stats = percentiles(np.arange(1, 101), scale=2.0)
    assert stats["p50"] == pytest.approx(101.0) and stats["p99"] == pytest.approx(198.02) and stats["n"] == 100
    assert math.isnan(percentiles([])["p99"])


def test_missed_periods_counts_the_periods_without_an_event():
    assert missed_periods([0.0, 0.002, 0.006, 0.008, 0.014], 0.002) == 3
    assert missed_periods([0.0, 0.0021, 0.0039], 0.002) == 0


def test_period_jitter_is_the_deviation_from_the_period():
    np.testing.assert_allclose(period_jitter([0.0, 0.0021, 0.0039], 0.002), [1e-4, 2e-4], atol=1e-12)


def test_bursts_start_at_the_first_frame_after_a_gap():
    assert group_bursts([0.0, 1e-5, 2e-5, 2e-3, 2.01e-3], 5e-4) == [0.0, 2e-3]


def _frame(t, node, cmd, data=b"\0" * 8):
    return Frame(t, node << 5 | cmd, len(data), False, False, data)


def test_analyse_a_synthetic_capture():
    period = 0.002
    frames = []
    for k in range(500):
        tick = 0.001 + k * period
        for node in range(3):
            frames.append(_frame(tick - 0.0007, node, CommandId.GET_ENCODER_ESTIMATES))   # 0.7 ms before the tick
            sign = 1.0 if (tick // 0.01) % 2 == 0 else -1.0                           # operator flips every 10 ms
            frames.append(_frame(tick + 0.0001 + 1e-5 * node, node, CommandId.SET_INPUT_TORQUE,
                                 struct.pack("<ff", sign, 0.0)[:4]))
    # 3 ms before the flip; next burst 1.1 ms after it
    operator = [(j * 0.01 - 0.003, 1.0 if j % 2 == 0 else -1.0) for j in range(1, 100)]
    figures = analyse(frames, operator, (0.0, 1.0), 500.0, {})
    assert figures["loop"]["rate_hz"] == pytest.approx(500.0)
    assert figures["loop"]["deadline_misses"] == 0
    assert figures["loop"]["jitter_p99_us"] == pytest.approx(0.0, abs=1e-3)
    assert figures["latency"]["sensor_to_torque_us"]["p50"] == pytest.approx(800.0, abs=1e-3)
    assert figures["latency"]["operator_to_torque_us"]["p50"] == pytest.approx(3000.0 + 1100.0, abs=1.0)
    assert figures["bus_load"]["fraction_1mbit"] == pytest.approx((1500 * 135 + 1500 * 95) / 1e6, rel=1e-3)


def test_targets_are_judged_and_unmeasured_figures_become_null():
    report = {"control_step_us": {"ce": {"median": 40.0}}, "bus_load": {"fraction_1mbit": 0.7},
              "loop": {"jitter_p99_us": math.nan}}
    targets = check_targets(report)
    assert targets["control_step_us.ce.median"]["met"] is True
    assert targets["bus_load.fraction_1mbit"]["met"] is False
    assert targets["loop.jitter_p99_us"]["met"] is None
    assert finite_or_null({"a": [math.inf, 1.0]}) == {"a": [None, 1.0]}


def test_the_daemons_json_summary_is_read_in_the_benchs_names(tmp_path):
    from sharedctl.services.studies.bench.stack_run import daemon_summary

    path = controller_json(tmp_path, ticks=9000, rate_hz=500.0, missed=1, late=2, jitter_p50_us=10.0,
                           jitter_p99_us=90.0, jitter_max_us=1000.0, compute_p50_us=360.0, compute_p99_us=1130.0,
                           torque_out_p50_us=340.0, torque_out_p99_us=530.0, sensor_to_torque_p50_us=610.0,
                           sensor_to_torque_p99_us=920.0, loop_cpu_p50_us=810.0, loop_cpu_p99_us=1520.0,
                           cpu_percent=43.4, sensor_waits=12, sensor_waits_in_vain=3, frames_rx=63000,
                           rejections={"stale": 1}, mode="running")
    got = daemon_summary(path)
    assert (got["missed"], got["late"], got["compute_p50_us"], got["torque_out_p50_us"], got["torque_out_p99_us"]) == (
        1, 2, 360.0, 340.0, 530.0)
    assert (got["lateness_p50_us"], got["lateness_p99_us"], got["lateness_max_us"]) == (10.0, 90.0, 1000.0)
    assert (got["sensor_to_torque_p50_us"], got["loop_cpu_p50_us"], got["loop_cpu_p99_us"]) == (610.0, 810.0, 1520.0)
    assert (got["cpu_percent"], got["sensor_waits"], got["sensor_waits_in_vain"],
            got["frames_rx"]) == (43, 12, 3, 63000)
    assert "rejections" not in got and "mode" not in got     # what the bench does not report, it does not carry


def test_a_controller_that_wrote_no_summary_has_none(tmp_path):
    from sharedctl.services.studies.bench.stack_run import daemon_summary

    assert daemon_summary(tmp_path / "controller.json") == {}


def test_estimates_that_arrived_after_the_tick_started_are_not_counted_as_used():
    """Estimates 0.3 ms before each burst; the tick started 0.25 ms before it (torque out) — they were used —
    while the whole compute time (0.5 ms, telemetry included) would have cut them off."""
    period, frames = 0.002, []
    for k in range(200):
        burst = 0.001 + k * period
        for node in range(3):
            frames.append(_frame(burst - 0.0003, node, CommandId.GET_ENCODER_ESTIMATES))
            frames.append(_frame(burst + 1e-5 * node, node, CommandId.SET_INPUT_TORQUE, struct.pack("<f", 1.0)))
    with_out = analyse(frames, [], (0.0, 0.4), 500.0, {"compute_p50_us": 500.0, "torque_out_p50_us": 250.0,
                                                          "missed": 0, "late": 0})
    compute_only = analyse(frames, [], (0.0, 0.4), 500.0, {"compute_p50_us": 500.0, "missed": 0, "late": 0})
    assert with_out["latency"]["sensor_to_torque_us"]["p50"] == pytest.approx(300.0, abs=1e-3)
    assert compute_only["latency"]["sensor_to_torque_us"]["p50"] == pytest.approx(2300.0, abs=1e-3)


def test_the_causes_of_missed_deadlines_are_read_from_the_daemons_summary(tmp_path):
    from sharedctl.services.studies.bench.stack_run import daemon_summary

    got = daemon_summary(controller_json(tmp_path, missed=3, late=4, misses_woke_late=2, misses_not_run=4,
                                         misses_working=1, misses_working_cpu_p50_us=2250.0,
                                         misses_working_frames_p50=7.0, misses_working_commands_p50=1.5))
    assert (got["missed"], got["late"], got["misses_woke_late"], got["misses_not_run"], got["misses_working"]) == (
        3, 4, 2, 4, 1)
    assert got["misses_working_cpu_p50_us"] == 2250.0
    assert (got["misses_working_frames_p50"], got["misses_working_commands_p50"]) == (7.0, 1.5)
    assert got["miss_times"] == []


def test_the_first_misses_times_are_read_from_the_daemons_summary_and_merged_over_controllers(tmp_path):
    from sharedctl.services.studies.bench.markdown import _miss_times
    from sharedctl.services.studies.bench.stack_run import daemon_summary, merge_summaries

    got = daemon_summary(controller_json(tmp_path, missed=1, late=1, miss_times=[
        {"t_s": 0.3125, "cause": "working"}, {"t_s": 12.0, "cause": "not running"}]))
    assert got["miss_times"] == [[0.3125, "working"], [12.0, "not running"]]
    merged = merge_summaries([got, dict(got, miss_times=[[1.5, "woke late"]])])
    assert merged["miss_times"] == [[0.3125, "working"], [12.0, "not running"], [1.5, "woke late"]]
    assert _miss_times(got["miss_times"]) == "0.31 (working), 12.00 (not running)"
    assert (_miss_times([]), _miss_times(None)) == ("none", "—")


def test_the_output_instant_and_the_compute_before_it_are_read_from_the_daemons_summary(tmp_path):
    from sharedctl.services.studies.bench.stack_run import daemon_summary

    held = daemon_summary(controller_json(tmp_path, torque_ready_p50_us=210.0, torque_ready_p99_us=480.0,
                                          torque_at_us=350.0))
    at_once = daemon_summary(controller_json(tmp_path, torque_ready_p50_us=200.0, torque_at_us=0.0))
    assert (held["torque_ready_p50_us"], held["torque_ready_p99_us"], held["torque_at_us"]) == (210.0, 480.0, 350.0)
    assert at_once["torque_at_us"] == 0.0 and at_once["torque_ready_p50_us"] == 200.0


def test_several_controllers_summaries_are_summed_and_their_percentiles_labelled_worst_or_median():
    from sharedctl.services.studies.bench.stack_run import merge_summaries

    a = {"ticks": 100, "rate_hz": 500.0, "missed": 1, "late": 2, "lateness_p99_us": 50.0, "torque_out_p50_us": 200.0,
         "misses_working_cpu_p50_us": None}
    b = {"ticks": 300, "rate_hz": 400.0, "missed": 3, "late": 0, "lateness_p99_us": 90.0, "torque_out_p50_us": 260.0,
         "misses_working_cpu_p50_us": 2000.0}
    c = dict(b, torque_out_p50_us=220.0)
    got = merge_summaries([a, b, c])
    assert (got["ticks"], got["missed"], got["late"], got["turns"]) == (700, 7, 2, 3)
    assert got["lateness_p99_us"] == 90.0 and got["torque_out_p50_us"] == 220.0
    assert got["rate_hz"] == pytest.approx((100 * 500 + 600 * 400) / 700)
    assert got["misses_working_cpu_p50_us"] is None          # not known for every controller: not made up
    assert merge_summaries([a]) is a
    assert merge_summaries([a, {}]) == {}                    # one line missing: no sum that undercounts


def test_turns_are_analysed_window_by_window_never_across_the_gap_between_them():
    """Two 0.2 s windows of perfect 500 Hz bursts, 0.3 s apart, on a phase that does not continue across the
    gap: no interval spans the gap, so the jitter stays 0 and no period counts as missed."""
    period, frames = 0.002, []
    for start in (0.0, 0.5003):
        for k in range(100):
            t = start + 0.001 + k * period
            for node in range(3):
                frames.append(_frame(t - 0.0003, node, CommandId.GET_ENCODER_ESTIMATES))
                frames.append(_frame(t + 1e-5 * node, node, CommandId.SET_INPUT_TORQUE, struct.pack("<f", 1.0)))
    windows = [(0.0, 0.2), (0.5003, 0.7003)]
    one = {"missed": 1, "late": 0, "torque_out_p50_us": 250.0}
    got = analyse_turns(frames, [], windows, 500.0, [one, dict(one, missed=2)])
    assert got["loop"]["jitter_p99_us"] == pytest.approx(0.0, abs=1e-3)
    assert got["loop"]["periods_without_torque_on_bus"] == 0
    assert got["loop"]["bursts"] == 200 and got["loop"]["rate_hz"] == pytest.approx(500.0)
    assert got["loop"]["deadline_misses"] == 3                 # the controllers' own counts, summed
    assert got["latency"]["sensor_to_torque_us"]["n"] == 200
    joined = analyse(frames, [], (0.0, 0.7003), 500.0, {})    # one window over the gap: the gap shows
    assert joined["loop"]["periods_without_torque_on_bus"] > 100


def test_the_floor_figures_pool_runs_without_an_interval_across_them():
    from sharedctl.services.studies.bench.machine_floor import figures

    def run(first_sent_ns, misses):
        n = 50
        return {"rate_hz": 500.0, "seconds": 0.1, "work_us": 100.0, "pre_send_us": 50.0, "hold_us": 0.0,
                "realtime": False, "cpu": None, "on_bus": False, "ticks": n, "missed": misses, "late": 1,
                "steal_s": 0.01, "samples": {"lateness": np.zeros(n), "wall": np.full(n, 1e5), "cpu": np.full(n, 1e5),
                                             "sent": first_sent_ns + 2e6 * np.arange(n), "pre_wall": np.full(n, 5e4)}}

    got = figures([run(0.0, 2), run(7.3e9, 0)])
    assert (got["ticks"], got["missed"], got["late"], got["deadline_misses"], got["runs"]) == (100, 2, 2, 4, 2)
    assert got["send_jitter_us"]["max"] == 0.0 and got["steal_s"] == pytest.approx(0.02)


def test_the_bare_loop_reads_frames_on_the_daemons_schedule():
    from sharedctl.services.studies.bench import machine_floor
    from sharedctl.services.controller import daemon

    assert (machine_floor.RECEIVE_MARGIN, machine_floor.RECEIVE_SLICE) == (daemon.RECEIVE_MARGIN, daemon.RECEIVE_SLICE)


def test_the_work_of_overrunning_periods_comes_only_from_controllers_that_had_them():
    from sharedctl.services.studies.bench.stack_run import merge_summaries

    quiet = {"ticks": 100, "rate_hz": 500.0, "misses_working": 0, "misses_working_cpu_p50_us": 0.0}
    busy = {"ticks": 100, "rate_hz": 500.0, "misses_working": 10, "misses_working_cpu_p50_us": 2900.0}
    assert merge_summaries([quiet, quiet, busy])["misses_working_cpu_p50_us"] == 2900.0
    assert merge_summaries([quiet, quiet])["misses_working_cpu_p50_us"] == 0.0


def test_the_operator_latency_is_split_by_the_publisher_of_each_command():
    period, frames = 0.002, []
    for k in range(500):
        tick = 0.001 + k * period
        sign = 1.0 if (tick // 0.01) % 2 == 0 else -1.0                             # operator flips every 10 ms
        for node in range(3):
            frames.append(_frame(tick - 0.0007, node, CommandId.GET_ENCODER_ESTIMATES))
            frames.append(_frame(tick + 0.0001 + 1e-5 * node, node, CommandId.SET_INPUT_TORQUE,
                                 struct.pack("<ff", sign, 0.0)[:4]))
    # commands in pairs, one of each sign, by turns on Zenoh's default QoS (sent 3 ms before the flip) and on the
    # stream's (1 ms before it); the next burst is 1.1 ms after the flip
    operator = []
    for j in range(1, 100):
        label = "default" if (j - 1) // 2 % 2 == 0 else "streams"
        operator.append((j * 0.01 - (0.003 if label == "default" else 0.001), 1.0 if j % 2 == 0 else -1.0, label))
    latency = analyse(frames, operator, (0.0, 1.0), 500.0, {})["latency"]
    assert latency["operator_to_torque_by_qos_us"]["default"]["p50"] == pytest.approx(3000.0 + 1100.0, abs=1.0)
    assert latency["operator_to_torque_by_qos_us"]["streams"]["p50"] == pytest.approx(1000.0 + 1100.0, abs=1.0)
    assert latency["operator_to_torque_by_qos_us"]["default"]["n"] + \
        latency["operator_to_torque_by_qos_us"]["streams"]["n"] == latency["operator_to_torque_us"]["n"]
