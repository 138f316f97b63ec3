"""Fault specifications: what each SPEC string means, and the typed error for a bad one."""
from __future__ import annotations

import math

import pytest

from sharedctl.services.faults.impairments import BernoulliLoss, Blackout, Corrupt, Delay, GilbertElliott, Replay
from sharedctl.services.faults.spec import FaultSpecError, ProcessFault, parse, pipeline, stages


def test_no_specs_is_an_empty_plan_with_no_stages():
    plan = parse([])
    assert plan.empty and not any(plan.has(s) for s in ("operator", "telemetry", "can"))
    assert pipeline(plan, "operator").empty


def test_operator_link_keys():
    plan = parse(["operator.delay_ms=300", "operator.jitter=pareto:50", "operator.loss=50%", "operator.burst=0.05,0.5",
                  "operator.blackout=2,5", "operator.blackout=10,1", "operator.duplicate=0.1", "operator.reorder=0.2",
                  "operator.corrupt=0.01,4", "operator.rate=20,5", "operator.replay=0.1,800"])
    link = plan.links["operator"]
    assert (link.delay_ms, link.jitter_ms, link.jitter_dist, link.loss) == (300, 50, "pareto", 0.5)
    assert link.burst == (0.05, 0.5) and link.blackouts == [(2, 5), (10, 1)]
    assert link.reorder == (0.2, 50.0) and link.corrupt == (0.01, 4) and link.rate == (20, 5)
    assert link.replay == (0.1, 800) and link.duplicate == 0.1
    assert plan.has("operator") and not plan.has("telemetry")
    kinds = [type(s) for s in stages(link)]
    assert kinds[:3] == [Blackout, BernoulliLoss, GilbertElliott] and Corrupt in kinds and Replay in kinds
    delay = next(s for s in stages(link) if isinstance(s, Delay))
    assert (delay.delay, delay.jitter, delay.distribution) == (0.3, 0.05, "pareto")


def test_jitter_ms_is_uniform_and_telemetry_has_the_same_keys():
    plan = parse(["telemetry.jitter_ms=20", "telemetry.loss=0.1"])
    assert plan.links["telemetry"].jitter_dist == "uniform" and plan.links["telemetry"].loss == 0.1


def test_can_keys():
    plan = parse(["can.loss=0.05", "can.delay_ms=2", "can.ids=feedback", "can.busoff=3,0.5", "can.babble=2000"])
    can = plan.links["can"]
    assert can.ids == ("feedback",) and can.blackouts == [(3, 0.5)]
    assert can.babble == (2000, 0x000, 0.0, math.inf)
    assert parse(["can.ids=0x2E,0x4e"]).links["can"].ids == (0x2E, 0x4E)
    assert parse(["can.babble=500,0x10,1,2"]).links["can"].babble == (500, 0x10, 1, 2)


def test_process_faults_sorted_by_time():
    plan = parse(["controller.restart_at=6", "controller.kill_at=5", "console.kill_at=2", "robot.stop_at=1,0.5"])
    assert plan.processes == [ProcessFault("robot", "stop", 1, 0.5), ProcessFault("console", "kill", 2),
                              ProcessFault("controller", "kill", 5), ProcessFault("controller", "restart", 6)]


def test_an_operator_estop_is_a_timed_process_fault_that_needs_no_relay():
    plan = parse(["operator.estop_at=2.4", "operator.delay_ms=300"])
    assert plan.processes == [ProcessFault("operator", "estop", 2.4)]
    assert plan.processes[0].describe() == "operator.estop_at=2.4"
    assert not parse(["operator.estop_at=2.4"]).has("operator")     # the demo sends it, not the relay


def test_seed_from_the_option_or_a_spec():
    assert parse([], seed=7).seed == 7
    assert parse(["seed=11"], seed=7).seed == 11
    a, b = pipeline(parse(["operator.loss=0.5"], 1), "operator"), pipeline(parse(["operator.loss=0.5"], 1), "operator")
    assert [a.feed(0, b"x") for _ in range(50)] == [b.feed(0, b"x") for _ in range(50)]


@pytest.mark.parametrize("spec,names", [
    ("operator.loss=1.5", "operator.loss=1.5"),
    ("operator.loss=abc", "abc"),
    ("operator.estop_at=-1", "-1"),
    ("operator.loss=nan", "nan"),
    ("operator.delay_ms=-5", "-5"),
    ("operator.color=red", "operator.color"),
    ("wheel.loss=0.1", "wheel"),
    ("operator.burst=0.1", "P,R"),
    ("operator.jitter=gamma:5", "DIST:MS"),
    ("operator.blackout=3", "START,DURATION"),
    ("operator.busoff=1,2", "busoff"),
    ("can.ids=0x900", "0x900"),
    ("can.babble=100,0x1,2", "START and DURATION"),
    ("can.babble=10000", "10000"),
    ("console.restart_at=3", "console.restart_at"),
    ("controller.restart_at=3", "kill_at"),
    ("operator.loss", "KEY=VALUE"),
    ("seed=x", "seed"),
])
def test_a_bad_spec_is_a_typed_error_naming_it(spec, names):
    with pytest.raises(FaultSpecError) as err:
        parse([spec])
    assert names in str(err.value) and err.value.spec


def test_a_key_given_twice_is_refused_but_windows_add_up():
    with pytest.raises(FaultSpecError, match="twice"):
        parse(["operator.loss=0.1", "operator.loss=0.2"])
    assert len(parse(["can.busoff=1,1", "can.busoff=3,1"]).links["can"].blackouts) == 2


def test_intrusions_are_timed_faults_with_their_defaults_and_describe_themselves_back():
    plan = parse(["robot.reboot_at=2", "can.intruder_at=1.5,500", "operator.flood_at=1", "operator.evict_at=3",
                  "router.restart_at=2,0.5"])
    got = {(f.target, f.action): (f.at, f.duration, f.params) for f in plan.processes}
    assert got == {("robot", "reboot"): (2.0, 0.5, (1.0, 0.5)), ("can", "intrude"): (1.5, 0.5, (500.0, 0.5)),
                   ("operator", "flood"): (1.0, 1.0, (2000.0, 1.0)), ("operator", "evict"): (3.0, 0.0, ()),
                   ("router", "bounce"): (2.0, 0.5, (0.5,))}
    assert [parse([f.describe()]).processes[0] for f in plan.processes] == plan.processes
    assert not plan.has("can") and not plan.has("operator")       # no gateway, no relay


@pytest.mark.parametrize("specs, names", [
    (["robot.reboot_at=2,3"], "AXIS"),
    (["can.intruder_at=1,0.5"], "HZ"),
    (["operator.flood_at=1,100,0"], "DURATION"),
    (["router.restart_at=1,0"], "DOWN"),
    (["can.intruder_at=1", "can.loss=0.1"], "gateway"),
])
def test_a_bad_intrusion_is_a_typed_error_naming_it(specs, names):
    with pytest.raises(FaultSpecError) as err:
        parse(specs)
    assert names in str(err.value)
