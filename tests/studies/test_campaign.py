"""The fault campaign without processes: its matrix, its judge, its aggregate and report, and the
stopping-distance analysis (docs/safety.md) it judges with."""
from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from sharedctl.services.studies.campaign import judge as jd
from sharedctl.services.studies.campaign import matrix as cp
from sharedctl.services.studies.campaign import stopping
from sharedctl.services.studies.campaign.report import grid_cells, write_report
from sharedctl.services.robot.plant import Plant, RobotSimConfig
from sharedctl.services.scenario_files import load
from sharedctl.scenario import parse
from sharedctl.models import OmniRobot

FAMILIES = ("operator.delay_ms", "operator.loss", "operator.burst", "operator.blackout", "operator.duplicate",
            "operator.reorder", "operator.corrupt", "operator.replay", "telemetry.", "can.loss", "can.delay_ms",
            "can.corrupt", "can.busoff", "can.babble", "controller.kill_at", "controller.stop_at", "console.kill_at",
            "robot.kill_at")
NEW_FAMILIES = ("operator.estop_at",)


def _specs(cases):
    return [f for c in cases for f in c.faults]


def _values(cases, key):
    return sorted({float(f.split("=")[1]) for f in _specs(cases) if f.startswith(key + "=")})


def test_quick_plan_covers_every_fault_family_in_at_least_20_runs():
    cases = cp.plan(quick=True)
    assert len(cases) >= 20
    for family in FAMILIES:
        assert any(f.startswith(family) for f in _specs(cases)), family
    assert len({c.id for c in cases}) == len(cases)


def test_full_plan_sweeps_the_ranges_of_the_issue():
    cases = cp.plan(quick=False)
    assert len(cases) >= 200
    assert len({c.id for c in cases}) == len(cases)
    delays, losses = _values(cases, "operator.delay_ms"), _values(cases, "operator.loss")
    assert delays[0] <= 100 and delays[-1] == 1000 and len(delays) >= 6
    assert losses[-1] == 1.0 and len(losses) >= 5
    assert _values(cases, "can.loss")[-1] == 0.2
    assert any(f.startswith("operator.blackout=") and f.endswith(",5") for f in _specs(cases))
    for family in FAMILIES + NEW_FAMILIES:
        assert any(f.startswith(family) for f in _specs(cases)), family
    # kills and hangs land before, during and after the fast approach to the wall (~1.2 m/s at 1.5–2.3 s)
    kill_times = [c.fault_value("controller.kill_at")[0] for c in cases
                  if c.scenario == cp.ADVERSARIAL and c.fault_value("controller.kill_at")]
    assert min(kill_times) < 1.0 and any(1.5 <= t <= 2.3 for t in kill_times) and max(kill_times) > 3.0


def test_full_plan_reaches_the_can_envelope_in_steps():
    """CAN delay up to 25 ms each way, alone and with 20 % loss, with steps below it, on both scenarios."""
    cases = cp.plan(quick=False)
    delays = _values(cases, "can.delay_ms")
    assert delays[-1] == 25 and {2, 5, 10, 15, 20} <= set(delays)
    for scenario in (cp.ADVERSARIAL, cp.PAPER):
        assert any(c.scenario == scenario and set(c.faults) == {"can.delay_ms=25", "can.loss=0.2"} for c in cases)
    mixed = {(c.fault_value("can.loss")[0], c.fault_value("can.delay_ms")[0]) for c in cases
             if c.scenario == cp.ADVERSARIAL and c.family == "can.delay_ms+can.loss"}
    assert {(0.2, d) for d in (2, 5, 10, 15, 20, 25)} <= mixed


def _instants(cases, key, duration=None):
    """The instants of `key` in the sweeps: the adversarial cases with that fault alone, unsecured."""
    return sorted(c.fault_value(key)[0] for c in cases if c.scenario == cp.ADVERSARIAL and c.fault_value(key)
                  and len(c.faults) == 1 and not c.secure
                  and (duration is None or c.fault_value(key)[1] == duration))


@pytest.mark.parametrize("key, duration", [("controller.kill_at", None), ("operator.estop_at", None),
                                           ("controller.stop_at", 0.1), ("controller.stop_at", 0.09),
                                           ("controller.stop_at", 0.05)])
def test_full_plan_puts_kills_hangs_up_to_the_watchdog_and_estops_at_every_tenth_of_the_approach(key, duration):
    """The approach window measured on the sampled loop (the robot within D(v_peak) of the wall until at rest)
    is covered at every 0.1 s, with at least one instant either side of it."""
    samples, plant, feasible = stopping.sampled_loop(load(cp.ADVERSARIAL), 3.5)
    start, end, peak, reach = stopping.approach_window(samples, plant, feasible)
    assert peak > 1.0 and 0.3 < reach < 0.6                     # the adversary drives at the wall
    instants = _instants(cp.plan(quick=False), key, duration)
    inside = [t for t in instants if start - 0.1 <= t <= end + 0.1]
    assert min(instants) < start and max(instants) > end
    assert len(inside) >= 2 and np.allclose(np.diff(inside), 0.1)
    assert math.floor((end - start) / 0.1) <= len(inside) - 1


def test_the_quick_plan_is_unchanged_by_the_new_envelope_and_meets_each_intruder_once():
    ids = [c.id for c in cp.plan(quick=True)]
    assert len(ids) == 25 and "adversarial_wall|controller.kill_at=1.9|4s" in ids
    secure = [c for c in cp.plan(quick=True) if c.secure]       # the secured stack meets a link fault too
    assert len(secure) == 1 and any(f.startswith("operator.") for f in secure[0].faults)
    assert not any("estop_at" in i or "can.delay_ms=25" in i for i in ids)
    for key in ("controller.restart_at", "robot.reboot_at", "can.intruder_at", "operator.flood_at",
                "operator.evict_at"):
        assert sum(key in i for i in ids) == 1, key


def test_the_full_plan_has_every_intruder_family_and_a_secured_stack_meeting_faults():
    families = {c.family for c in cp.plan(quick=False)}
    assert {"controller.kill_at+controller.restart_at", "robot.reboot_at", "can.intruder_at", "operator.flood_at",
            "operator.evict_at", "secure:none", "secure:router.restart_at",
            "secure:controller.kill_at+controller.restart_at", "secure:can.intruder_at"} <= families
    secured = [c for c in cp.plan(quick=False) if c.secure]
    assert secured and all("--secure" in cp.demo_argv(c, Path("x.json")) for c in secured)


def test_every_planned_fault_parses_with_the_demo_parser():
    spec = pytest.importorskip("sharedctl.services.faults.spec")
    assert cp.validate(cp.plan(quick=False) + cp.plan(quick=True), spec.parse) == {}


def test_demo_argv_is_a_headless_measured_demo_with_one_fault_option_per_spec(tmp_path):
    case = cp.Case("adversarial_wall", ("operator.delay_ms=300", "can.loss=0.1"), 6.0, "nce")
    argv = cp.demo_argv(case, tmp_path / "out.json")
    assert argv[argv.index("demo") + 1:argv.index("demo") + 3] == ["--scenario", "adversarial_wall"]
    assert {"--headless", "--no-reference"} <= set(argv)
    assert argv[argv.index("--json") + 1] == str(tmp_path / "out.json")
    assert argv[argv.index("--duration") + 1] == "6" and argv[argv.index("--controller") + 1] == "nce"
    assert [argv[i + 1] for i, a in enumerate(argv) if a == "--fault"] == list(case.faults)


@pytest.mark.parametrize("faults, expected", [
    (("controller.kill_at=2",), ("controller.kill_at", 2.0, (0.098, 0.1))),
    (("controller.stop_at=1.5,0.3",), ("controller.stop_at", 1.5, (0.098, 0.1))),
    (("controller.stop_at=1.5,0.1",), ("controller.stop_at", 1.5, (0.098, 0.1))),   # T_w: the watchdog may trip
    (("controller.stop_at=1.5,0.05",), None),         # shorter than the watchdog: the drives never disarm
    (("can.busoff=3,1",), ("can.busoff", 3.0, (0.098, 0.1))),
    (("can.busoff=3,0.03",), None),                   # shorter than the feedback timeout
    (("operator.estop_at=2.4",), ("operator.estop_at", 2.4, (0.0, 0.004))),   # disarmed at once, or periods later
    (("operator.delay_ms=300", "console.kill_at=1"), None),
])
def test_actuation_loss_is_what_disarms_the_drives(faults, expected):
    loss = cp.Case("adversarial_wall", faults).actuation_loss()
    assert loss == (expected if expected is None else (expected[0], expected[1], pytest.approx(expected[2])))


def test_a_hang_the_controller_may_resume_from_before_the_watchdog_is_a_short_hang():
    assert cp.Case("adversarial_wall", ("controller.stop_at=1.5,0.05",)).short_hang() == (1.5, 0.05)
    assert cp.Case("adversarial_wall", ("controller.stop_at=1.5,0.097",)).short_hang() == (1.5, 0.097)
    both = cp.Case("adversarial_wall", ("controller.stop_at=1.5,0.097",)).actuation_loss()
    assert both[0] == "controller.stop_at" and both[2] == pytest.approx((0.097, 0.097))
    # the last frame went out at most a period before the stop: a hang of T_w always trips the watchdog
    assert cp.Case("adversarial_wall", ("controller.stop_at=1.5,0.1",)).short_hang() is None
    assert cp.Case("adversarial_wall", ("controller.stop_at=1.5,0.3",)).short_hang() is None


def _summary(violations=0, min_margin=0.03, estop_t=None, first=None, states=()):
    log = [{"t": estop_t, "at": estop_t, "kind": "estop"}] if estop_t is not None else []
    return {"violations": violations, "min_margin": min_margin, "truth_samples": 500, "estops": len(log),
            "event_log": log, "first_violation_t": first, "injected": {"operator": {"dropped": 7}},
            "fault_states": [{"what": what, "t": t, "truth": [[t, 0.0, 3.5, 0.0, 0.0, 1.2, 0.0]], "torques": []}
                             for what, t in states]}


class _Forecast:
    """Forecasts that answer `margin` whatever they are asked, and remember what they were asked."""

    def __init__(self, margin, delayed=0.01):
        self.margin, self.delayed = margin, delayed
        self.coasts, self.delays = [], []

    def coast(self, scenario, controller, state, holds):
        self.coasts.append((state, holds))
        return {"t_fault": state["t"], "approach_speed": 1.2, "margin": 0.6, "min_margin": self.margin,
                "speed": 1.2}

    def delay(self, scenario, duration, controller, loop_delay, hang):
        self.delays.append((loop_delay, hang))
        return {"min_margin": self.delayed, "best_min_margin": self.delayed}


def _forecast(margin, delayed=0.01):
    return _Forecast(margin, delayed)


def test_a_violation_without_a_loss_of_actuation_is_unexpected():
    row = jd.judge(cp.Case("adversarial_wall", ("operator.delay_ms=300",)),
                   jd.RunResult(_summary(3, -0.01, first=2.5), 1, 9.0), _forecast(-1.0))
    assert row["outcome"] == "violation" and row["documented"] is False and row["forecast"] is None


def test_a_violation_after_a_kill_at_speed_is_documented_only_if_its_forecast_leaves_the_set():
    case = cp.Case("adversarial_wall", ("controller.kill_at=2",))
    result = jd.RunResult(_summary(40, -0.9, first=2.6, states=[("controller.kill_at=2", 2.003)]), 1, 9.0)
    row = jd.judge(case, result, _forecast(-1.1))
    assert row["documented"] is True and "even at best" in row["explained"]
    assert jd.judge(case, result, _forecast(0.2))["documented"] is False


def test_the_forecast_of_a_kill_starts_from_the_instant_it_actually_fired_with_the_watchdog_holds():
    case = cp.Case("adversarial_wall", ("controller.kill_at=2",))
    forecasts = _forecast(-1.1)
    jd.judge(case, jd.RunResult(_summary(40, -0.9, first=2.6, states=[("controller.kill_at=2", 2.0317)]), 1, 9.0),
             forecasts)
    (state, holds), = forecasts.coasts
    assert state["t"] == 2.0317 and holds == pytest.approx((0.098, 0.1))


def test_a_kill_without_the_ground_truth_at_its_instant_has_no_forecast_and_is_unexpected():
    row = jd.judge(cp.Case("adversarial_wall", ("controller.kill_at=2",)),
                   jd.RunResult(_summary(40, -0.9, first=2.6), 1, 9.0), _forecast(-1.1))
    assert row["forecast"] is None and row["documented"] is False


def test_an_injected_estop_is_forecast_with_the_drives_driving_on_until_the_controllers_own_estop():
    case = cp.Case("adversarial_wall", ("operator.estop_at=2.4",))
    summary = _summary(3, -0.006, estop_t=2.4016, first=2.48, states=[("operator.estop_at=2.4", 2.4001)])
    forecasts = _forecast(-0.002)
    row = jd.judge(case, jd.RunResult(summary, 1, 9.0), forecasts)
    (state, holds), = forecasts.coasts                              # no second forecast for the same estop
    assert state["t"] == 2.4001 and holds == pytest.approx((0.0015, 0.0025))
    assert row["documented"] is True and row["explained"].startswith("operator.estop_at at 2.400 s")


def test_a_short_hang_is_forecast_at_the_instant_it_actually_fired():
    case = cp.Case("adversarial_wall", ("controller.stop_at=2.2,0.05",))
    forecasts = _forecast(0.3, delayed=-0.01)
    row = jd.judge(case, jd.RunResult(_summary(5, -0.01, first=2.3, states=[("controller.stop_at=2.2,0.05", 2.2041)]),
                                      1, 9.0), forecasts)
    assert forecasts.delays == [(0.0, (2.2041, 0.05))] and row["documented"] is True


def test_a_hang_that_may_end_either_way_is_documented_only_if_both_of_its_outcomes_leave_the_set():
    case = cp.Case("adversarial_wall", ("controller.stop_at=2.2,0.097",))
    result = jd.RunResult(_summary(5, -0.01, first=2.4, states=[("controller.stop_at=2.2,0.097", 2.2)]), 1, 9.0)
    assert jd.judge(case, result, _forecast(-0.2, delayed=0.01))["documented"] is False
    assert jd.judge(case, result, _forecast(0.05, delayed=-0.01))["documented"] is False
    assert jd.judge(case, result, _forecast(-0.2, delayed=-0.01))["documented"] is True


def test_a_violation_under_can_delay_is_documented_only_if_the_delayed_loop_leaves_the_set_too():
    case = cp.Case("adversarial_wall", ("can.delay_ms=10",))
    assert case.loop_delay() == pytest.approx(0.02)
    result = jd.RunResult(_summary(5, -0.01, first=2.5), 1, 9.0)
    assert jd.judge(case, result, _forecast(0.3, delayed=-0.002))["documented"] is True
    assert jd.judge(case, result, _forecast(0.3, delayed=0.01))["documented"] is False


def test_an_estop_before_the_violation_documents_it_only_if_its_forecast_leaves_the_set():
    case = cp.Case("paper_convex", ("can.loss=0.2",))
    result = jd.RunResult(_summary(2, -0.01, estop_t=1.0, first=1.4, states=[("estop", 1.0)]), 1, 9.0)
    assert jd.judge(case, result)["documented"] is False                # no forecast: not an excuse
    assert jd.judge(case, result, _forecast(0.02))["documented"] is False
    forecasts = _forecast(-0.05)
    assert jd.judge(case, result, forecasts)["documented"] is True
    (state, holds), = forecasts.coasts
    assert state["t"] == 1.0 and 0.1 in holds                          # a lost Estop frame: the watchdog's hold


def test_a_run_without_ground_truth_is_an_error_row():
    row = jd.judge(cp.Case("paper_convex"), jd.RunResult(None, 2, 1.0, "no summary"))
    assert row["outcome"] == "error" and row["documented"] is True


ROBOT_EXIT = {"physics_steps": 4000, "missed_ticks": 2600, "skipped_s": 0.25, "elapsed_s": 4.25}
CONTROLLER_EXIT = {"ticks": 1900, "missed": 3, "late": 5, "jitter_max_us": 1250.0, "estops": 1}
HOST = {"robot_physics_steps": 4000.0, "robot_missed_ticks": 2600.0, "robot_skipped_s": 0.25,
        "controller_missed_deadlines": 3.0, "controller_late_ticks": 5.0, "controller_jitter_max_ms": 1.25,
        "controller_estops": 1.0}


def test_host_figures_come_from_the_json_the_robot_and_the_controller_wrote_in_the_log_dir(tmp_path):
    (tmp_path / "robot.json").write_text(json.dumps(ROBOT_EXIT))
    (tmp_path / "controller.json").write_text(json.dumps(CONTROLLER_EXIT))
    assert jd.host_figures(tmp_path) == HOST
    assert jd.overloaded(jd.host_figures(tmp_path))            # 2600 of 4000 physics ticks missed


def test_host_figures_come_from_the_childrens_summaries_in_the_demos_json():
    demo = {"processes": {"robot": {"exit_code": 0, "summary": ROBOT_EXIT},
                          "controller": {"exit_code": 0, "summary": CONTROLLER_EXIT}, "console": {"exit_code": 0}}}
    assert jd.host_figures(None, demo) == HOST


def test_printed_exit_lines_are_not_read_for_host_figures(tmp_path):
    (tmp_path / "robot.log").write_text("sharedctl robot: stopped after 4.25 s: physics steps 4000, missed ticks 2600, "
                                        "skipped 0.250 s\n")
    assert jd.host_figures(tmp_path) is None


def test_a_violation_on_a_host_whose_robot_missed_most_of_its_ticks_is_reported_never_excused(tmp_path):
    demo = dict(_summary(2, -0.01, first=2.5), processes={"robot": {"summary": ROBOT_EXIT}})
    row = jd.judge(cp.Case("adversarial_wall", ("operator.delay_ms=300",)), jd.RunResult(demo, 1, 9.0))
    assert row["host"]["robot_missed_ticks"] == 2600.0 and row["overloaded"] is True
    assert row["documented"] is False and row["explained"] is None
    result = jd.aggregate([row])
    assert result["overload_violations"] == [row["id"]] and result["unexpected_violations"] == [row["id"]]


def test_campaign_runs_every_case_in_order_and_aggregates():
    cases = cp.plan(quick=True)[:5]
    margins = [0.03, 0.02, -0.4, 0.05, 0.01]

    def runner(case, index):
        v = 10 if margins[index] < 0 else 0
        return jd.RunResult(_summary(v, margins[index], first=1.0 if v else None), int(bool(v)), 8.0 + index)

    seen = []
    rows = cp.run_campaign(cases, runner, None, lambda row, done, total: seen.append((done, total)))
    result = jd.aggregate(rows)
    assert [r["id"] for r in rows] == [c.id for c in cases] and seen[-1] == (5, 5)
    assert result["runs"] == 5 and result["violations"] == 10 and result["violating_runs"] == 1
    assert result["min_margin"] == -0.4 and result["unexpected_violations"] == [cases[2].id]
    assert result["ok"] is False and sum(f["runs"] for f in result["families"].values()) == 5


def test_a_run_estopped_before_its_start_is_run_again_once():
    early = dict(_summary(), estops=1, event_log=[{"t": -0.5, "kind": "estop"}])
    results = iter([jd.RunResult(early, 1, 1.0), jd.RunResult(_summary(), 0, 1.0),
                    jd.RunResult(early, 1, 1.0), jd.RunResult(early, 1, 1.0)])
    rows = cp.run_campaign(cp.plan(quick=True)[:2], lambda c, i: next(results))
    assert [(r["outcome"], r["attempts"]) for r in rows] == [("safe", 2), ("not exercised", 2)]
    assert jd.aggregate(rows)["not_exercised"] == [rows[1]["id"]]


def test_an_estop_before_a_timed_fault_lands_leaves_the_fault_not_exercised():
    case = cp.Case("adversarial_wall", ("controller.stop_at=1.5,1",))
    assert case.fault_time() == 1.5 and cp.Case("adversarial_wall", ("can.loss=0.1",)).fault_time() is None
    before = dict(_summary(), estops=1, event_log=[{"t": 0.7, "kind": "estop"}])
    after = dict(_summary(), estops=1, event_log=[{"t": 1.6, "kind": "estop"}])
    assert jd.judge(case, jd.RunResult(before, 0, 1.0))["outcome"] == "not exercised"
    assert jd.judge(case, jd.RunResult(after, 0, 1.0))["outcome"] == "estop"


def test_campaign_stops_when_asked():
    calls = []
    rows = cp.run_campaign(cp.plan(quick=True), lambda c, i: calls.append(i) or jd.RunResult(_summary(), 0, 1.0),
                           should_stop=lambda: len(calls) >= 3)
    assert len(rows) == 3


def test_report_has_the_table_and_the_plots(tmp_path):
    grid = [cp.Case("adversarial_wall", tuple(f for f in (f"operator.delay_ms={d}" if d else "",
                                                          f"operator.loss={loss}" if loss else "") if f))
            for d in (0, 300) for loss in (0, 0.5)]
    kill = cp.Case("adversarial_wall", ("controller.kill_at=2",))
    rows = [jd.judge(c, jd.RunResult(_summary(0, 0.02 + 0.01 * i), 0, 8.0)) for i, c in enumerate(grid)]
    rows.append(jd.judge(kill, jd.RunResult(_summary(30, -0.8, first=2.7, states=[("controller.kill_at=2", 2.0)]),
                                            1, 8.0), _forecast(-1.1)))
    result = jd.aggregate(rows, {"command": "test"})
    jd.write_json(tmp_path / "c.json", result)
    assert json.loads((tmp_path / "c.json").read_text())["runs"] == 5
    assert grid_cells(rows) == {(0.0, 0.0): 0.02, (0.0, 0.5): 0.03, (300.0, 0.0): 0.04, (300.0, 0.5): 0.05}
    files = write_report(result, tmp_path / "report")
    names = {f.name for f in files}
    assert {"README.md", "margin_heatmap.png", "margin_by_family.png", "actuation_loss.png",
            "stopping_distance.png"} <= names
    text = (tmp_path / "report" / "README.md").read_text()
    assert "1 of 5 runs left the admissible set" in text and "`controller.kill_at=2`" in text
    assert text.count("\n| ") >= 5 + 3


# ----- the stopping-distance analysis -----------------------------------------------------------
@pytest.fixture(scope="module")
def plant():
    return Plant(OmniRobot(), RobotSimConfig())


def test_coast_deceleration_matches_the_plant_friction_and_brakes(plant):
    m1 = float(plant.model.theta[0])
    r, delta = plant.model.parameters.wheel_radius, plant.model.parameters.delta
    cfg = plant.config
    braked, unbraked = stopping.coast_model(plant, (0.0, 1.0)), stopping.coast_model(plant, (0.0, 1.0), braked=False)
    assert braked.coulomb == pytest.approx((cfg.friction_coulomb + cfg.brake_torque) * 2 * math.cos(delta) / r / m1)
    assert unbraked.coulomb == pytest.approx(cfg.friction_coulomb * 2 * math.cos(delta) / r / m1)
    assert braked.viscous == unbraked.viscous == pytest.approx(1.5 * cfg.friction_viscous / r**2 / m1)
    assert stopping.worst_coast_model(plant).coulomb == pytest.approx(braked.coulomb, rel=1e-3)


@pytest.mark.parametrize("brake_torque", [0.0, 1.0])
@pytest.mark.parametrize("speed", [0.2, 1.0])
def test_stopping_distance_formula_agrees_with_the_plant(speed, brake_torque):
    plant = Plant(OmniRobot(), RobotSimConfig(brake_torque=brake_torque))
    feasible = load("paper_convex").closed_loop(None)[0].feasible
    _, path, _ = stopping.coast(plant, feasible, np.array([0.0, 2.0, 0.0]), np.array([0.0, speed, 0.0]),
                                (0.0, 0.0, 0.0), hold=0.0)
    assert path == pytest.approx(stopping.coast_model(plant, (0.0, 1.0)).coast_distance(speed), rel=0.03)


def test_the_brakes_shorten_the_stop_from_1_m_s_more_than_fourfold(plant):
    unbraked = Plant(OmniRobot(), RobotSimConfig(brake_torque=0.0))
    assert (stopping.worst_coast_model(unbraked).stopping_distance(1.0)
            > 4 * stopping.worst_coast_model(plant).stopping_distance(1.0))


@pytest.mark.parametrize("distance", [0.025, 0.3, 0.6, 2.0])
def test_speed_limit_inverts_the_stopping_distance(plant, distance):
    model = stopping.worst_coast_model(plant)
    v = model.speed_limit(distance)
    assert 0 < v and model.stopping_distance(v) == pytest.approx(distance, rel=1e-6)


def without_backup(scenario):
    """The same scenario with `[backup] enabled = false`: the paper's loop without the governor."""
    data = copy.deepcopy(scenario.data)
    data["backup"] = {"enabled": False}
    return parse(data)


def test_torque_loop_delay_no_longer_erodes_the_margin_with_prediction_and_the_backup_governor():
    """A 30 ms and a 50 ms torque-loop delay (15 and 25 ms each way) on the adversarial wall: the
    paper's loop on the delayed state leaves the set at 30 ms; the default controller — told the
    feedback's age, it runs on the predicted state, with the backup governor — stays more than
    2 cm inside at both."""
    scenario = load("adversarial_wall")
    governed = [stopping.delayed_loop_margin(scenario, 3.0, lag)[0] for lag in (0.0, 0.03, 0.05)]
    paper = [stopping.delayed_loop_margin(without_backup(scenario), 2.6, lag, predictive=False)[0]
             for lag in (0.0, 0.03)]
    assert paper[0] > 0.01 and paper[1] < 0.0
    assert min(governed) > 0.02


def test_a_controller_loss_at_any_instant_of_the_approach_ends_inside_with_the_backup_governor():
    """The adversarial wall: the controller lost at every 50 ms of the first 3.5 s (the last torque
    held T_w, then the brakes). The paper's loop leaves the set for a loss at 2.3 s (1.3 m/s, 0.19 m
    from the face, as docs/safety.md §2 forecasts); with the governor no instant leaves it."""
    samples, plant, feasible = stopping.sampled_loop(without_backup(load("adversarial_wall")), 2.35)
    late = stopping.forecast(samples, plant, feasible, 2.3)
    assert late.approach_speed > 1.0 and late.min_margin < -0.1
    assert late.travelled == pytest.approx(late.predicted_distance, rel=0.1)
    samples, plant, feasible = stopping.sampled_loop(load("adversarial_wall"), 3.5)
    outcomes = [stopping.forecast(samples, plant, feasible, t) for t in np.arange(0.0, 3.5, 0.05)]
    assert max(o.speed for o in outcomes) > 1.0                 # the operator does drive fast
    assert min(o.min_margin for o in outcomes) > 0.02


def test_without_brakes_the_same_early_loss_coasts_out_of_the_set():
    samples, _, feasible = stopping.sampled_loop(load("adversarial_wall"), 2.05)
    unbraked = Plant(OmniRobot(), RobotSimConfig(brake_torque=0.0))
    coasting = stopping.forecast(samples, unbraked, feasible, 2.0)
    assert coasting.min_margin < -0.5
    assert coasting.travelled == pytest.approx(coasting.predicted_distance, rel=0.1)


# ----- the forecast from the ground truth at the instant a fault fired ---------------------------
def _row(t, y, vy):
    return [t, 0.0, y, 0.0, 0.0, vy, 0.0]


def test_state_at_interpolates_between_the_ground_truth_samples_around_the_instant():
    truth = [_row(1.0, 2.0, 1.0), _row(1.1, 2.1, 0.5)]
    t, q, qd = stopping.state_at(truth, 1.04)
    assert t == 1.04 and q == pytest.approx([0.0, 2.04, 0.0]) and qd == pytest.approx([0.0, 0.8, 0.0])
    assert stopping.state_at(truth, 0.9) is None
    assert stopping.state_at(truth, 1.2)[1] == pytest.approx([0.0, 2.1, 0.0])


@pytest.fixture
def wall():
    """The adversarial wall's set (y ≤ 4 the nearest face from x = 0, y > 3) and the robot's plant."""
    plant, feasible = stopping.true_plant(load("adversarial_wall"))
    # at rest 1 m from the wall until 2.05 s, then 0.1 m from it at 1 m/s toward it (a constructed trace)
    truth = [_row(round(t, 2), 3.0, 0.0) if t < 2.05 else _row(round(t, 2), 3.9, 1.0)
             for t in np.arange(1.9, 2.2, 0.01)]
    return plant, feasible, truth


def test_the_forecast_is_taken_from_the_state_at_the_instant_the_fault_fired_not_the_planned_one(wall):
    plant, feasible, truth = wall
    planned = stopping.forecast_at(plant, feasible, truth, [], 2.0, (0.0,))
    fired = stopping.forecast_at(plant, feasible, truth, [], 2.06, (0.0,))
    assert planned.margin == pytest.approx(1.0) and planned.speed == 0.0 and planned.min_margin == pytest.approx(1.0)
    # by hand: 0.1 m from the face at 1 m/s, braked at once: the face minus the braked stop D(1 m/s)
    braked = stopping.coast_model(plant, (0.0, 1.0)).stopping_distance(1.0, hold=0.0)
    assert fired.t_fault == 2.06 and fired.margin == pytest.approx(0.1) and fired.speed == pytest.approx(1.0)
    assert fired.min_margin == pytest.approx(0.1 - braked, abs=0.01) and fired.violates


def test_the_forecast_takes_the_better_of_the_last_reported_torque_and_the_one_the_truth_shows(wall):
    plant, feasible, truth = wall
    q = np.array([0.0, 3.9, 0.0])
    push, brake, harder = (plant.model.wheel_torques(q, np.array([0.0, f, 0.0])) for f in (20.0, -20.0, -60.0))
    torques = [[2.03, *push], [2.05, *brake], [2.07, *harder]]        # the last one is after the fault: not held
    outcome = stopping.forecast_at(plant, feasible, truth, torques, 2.06, (0.1,))
    held = {name: stopping.coast(plant, feasible, q, np.array([0.0, 1.0, 0.0]), tuple(tau), 0.1)[0]
            for name, tau in (("push", push), ("brake", brake), ("harder", harder))}
    assert held["push"] < held["brake"] < held["harder"]
    # the last reported before the fault, and the one the truth shows (constant speed: friction only)
    assert outcome.min_margin == pytest.approx(held["brake"]) and outcome.candidates == 2
    pushed = stopping.forecast_at(plant, feasible, truth, torques[:1], 2.06, (0.1,))
    assert pushed.min_margin > held["push"]          # the truth's (friction only) is better than the push


def test_the_torque_the_ground_truth_shows_is_the_torque_that_drove_the_plant():
    plant, _ = stopping.true_plant(load("adversarial_wall"))
    applied = (1.2, -0.8, 0.3)                                    # chosen; the oracle
    ps = plant.initial_state(np.array([0.0, 3.0, 0.1]), np.array([0.2, 0.8, 0.5]))
    truth = []
    for k in range(31):
        if k % 10 == 0:                                           # ground truth at 100 Hz, physics at 1 kHz
            truth.append([k * 0.001, *ps.q, *ps.qd])
        ps = plant.step(ps, applied, 0.001)
    assert stopping.torque_from_truth(plant, truth, 0.025) == pytest.approx(applied, rel=1e-3)
    assert stopping.torque_from_truth(plant, truth[:1], 0.025) is None
