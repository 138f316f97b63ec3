"""The 500 Hz run of `sharedctl bench` in turns (services/bench/stack_run.py): its bookkeeping, never its timing."""
import gc

import pytest

from sharedctl.services.studies.bench import stack_run

pytestmark = pytest.mark.processes      # starts the robot, two controllers and two bare loops


def test_controllers_and_bare_loops_take_turns_beside_one_robot_and_every_process_is_reaped():
    assert gc.isenabled()
    figures = stack_run.run(500.0, 2.0, probes=False, turns=2, floor=True, controller_args=("--torque-at-us", "350"))
    assert gc.isenabled()            # the run turns the collector off for itself only
    processes = figures["processes"]
    assert set(processes) == {"robot", "controller_1", "controller_2"}
    assert all(p["exit_code"] is not None and not p["killed"] for p in processes.values())
    daemon = figures["loop"]["daemon"]
    assert daemon["turns"] == 2 and len(figures["loop"]["daemon_turns"]) == 2
    assert daemon["ticks"] == sum(t["ticks"] for t in figures["loop"]["daemon_turns"])
    floor = figures["machine_floor"]
    assert floor["runs"] == 2 and len(floor["turns"]) == 2 and floor["on_bus"]
    assert floor["ticks"] == 2 * int(500.0 * (stack_run.SETTLE + 1.0 + 0.5))   # each as long as its controller ran
    # the bare loops' torque frames were seen on the bus, in their own windows
    assert floor["bus"]["bursts"] >= 0.9 * floor["ticks"]
    assert floor["hold_us"] == pytest.approx(daemon["torque_at_us"]) == 350.0   # the controller's output instant
