"""When `sharedctl demo --fault` carries out a timed fault (services/faults/stack.py), without processes: on the
run's clock, whose t = 0 is the lease instant, however late the demo learnt it. A fake clock and fake children."""
from __future__ import annotations

import json
import time
from types import SimpleNamespace

import pytest

from sharedctl.services.faults.spec import parse
from sharedctl.services.faults.stack import ESTOP_PERIOD, POLL, FaultStack, Injection
from sharedctl.services.faults.zenoh_relay import origin_monotonic


class Clock:
    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


class FakePopen:
    def __init__(self, pid: int) -> None:
        self.pid, self.returncode, self.signals = pid, None, []

    def poll(self):
        return self.returncode

    def kill(self) -> None:
        self.signals.append("SIGKILL")
        self.returncode = -9

    def wait(self):
        return self.returncode


def stack(specs, lease_at=100.0, learnt_at=100.03):
    """A FaultStack armed at `learnt_at` (the demo heard of the lease then) with t = 0 at `lease_at`."""
    plan = parse(specs)
    clock = Clock(learnt_at)
    faults = FaultStack(plan, injections=[Injection(f) for f in plan.processes], clock=clock)
    faults.arm(lease_at)
    return faults, clock


def child(pid=4242):
    popen = FakePopen(pid)
    return SimpleNamespace(popen=popen, name="controller", report=lambda: {"pid": pid}, exit_code=None,
                           stop_seconds=None)


def test_the_arming_reports_how_late_the_demo_learnt_the_lease():
    faults, _ = stack(["controller.kill_at=1"])
    assert faults.armed_at == pytest.approx(0.03)


def test_a_kill_is_due_at_its_time_after_the_lease_and_not_before():
    faults, clock = stack(["controller.kill_at=1"])
    children = {"controller": child()}
    clock.now = 100.999
    faults.tick(clock.now, children, restart=None)
    assert children["controller"].popen.signals == [] and faults.next_due() == pytest.approx(101.0)
    clock.now = 101.0
    faults.tick(clock.now, children, restart=None)
    assert children["controller"].popen.signals == ["SIGKILL"]
    report, = faults.report()["processes"]
    assert report["done_at"] == pytest.approx(1.0) and report["late_by"] == pytest.approx(0.0)
    assert faults.expected_dead("controller")


def test_the_supervision_loop_sleeps_no_longer_than_until_the_next_fault():
    faults, _ = stack(["operator.estop_at=0.5", "controller.kill_at=2"])
    assert faults.wait_time(100.2) == POLL                     # 0.3 s to go: the ordinary poll
    assert faults.wait_time(100.48) == pytest.approx(0.02)     # 20 ms to go: wake up then
    assert faults.wait_time(100.6) == 0.0                      # overdue: at once


def test_a_fault_fires_at_the_instant_the_clock_shows_and_reports_its_lateness():
    sent = []
    faults, clock = stack(["operator.estop_at=0.5"])
    faults.estop_sender = lambda: sent.append(clock.now)
    clock.now = 100.5037                                        # the loop woke 3.7 ms late
    faults.tick(clock.now, {}, restart=None)
    report, = faults.report()["processes"]
    assert sent == [100.5037] and report["done_at"] == pytest.approx(0.5037)
    assert report["late_by"] == pytest.approx(0.0037)


def test_the_estop_stays_held_until_the_run_ends_so_a_controller_started_after_it_still_gets_it():
    """`operator.estop_at` is a button held down, as the console's latched estop: one command every ESTOP_PERIOD from
    SEC on, the supervision loop waking for each; a wake-up 2.5 periods late sends one command, not the three it
    missed. Sent once, the estop was lost on a controller restarted shortly before it and not yet listening."""
    sent = []
    faults, clock = stack(["operator.estop_at=0.5"])
    faults.estop_sender = lambda: sent.append(clock.now)
    for dt in (0.0, 0.005, ESTOP_PERIOD + 0.0004, 2 * ESTOP_PERIOD + 0.001):      # each wake-up a little late
        clock.now = 100.5 + dt
        faults.tick(clock.now, {}, restart=None)
    assert sent == pytest.approx([100.5, 100.5 + ESTOP_PERIOD + 0.0004, 100.5 + 2 * ESTOP_PERIOD + 0.001])
    assert faults.next_due() == pytest.approx(100.5 + 3 * ESTOP_PERIOD)
    assert faults.wait_time(100.5 + 2.5 * ESTOP_PERIOD) == pytest.approx(0.5 * ESTOP_PERIOD)
    clock.now = 100.5 + 5.5 * ESTOP_PERIOD                      # the loop overslept
    faults.tick(clock.now, {}, restart=None)
    assert len(sent) == 4 and faults.next_due() == pytest.approx(100.5 + 6 * ESTOP_PERIOD)
    report, = faults.report()["processes"]
    assert report["done_at"] == pytest.approx(0.5) and report["sent"] == 4


def test_an_estop_without_a_session_is_skipped_and_says_why():
    faults, clock = stack(["operator.estop_at=0.5"])
    clock.now = 100.6
    faults.tick(clock.now, {}, restart=None)
    report, = faults.report()["processes"]
    assert report["done_at"] is None and "session" in report["skipped"]


def test_the_arming_writes_the_lease_instant_for_the_relay_and_the_gateway_before_it_signals(tmp_path):
    signalled = []
    origin = tmp_path / "fault-origin.json"
    gateway = SimpleNamespace(popen=SimpleNamespace(
        poll=lambda: None, send_signal=lambda sig: signalled.append(json.loads(origin.read_text()))))
    faults = FaultStack(parse(["can.busoff=2,0.3"]), infra={"gateway": gateway}, origin_file=origin,
                        clock=Clock(100.03))
    faults.arm(100.0, lease_wall=1_700_000_000.25)
    assert signalled == [{"lease_wall": 1_700_000_000.25}]


def test_the_relay_and_the_gateway_count_from_the_lease_instant_in_the_origin_file(tmp_path):
    origin = tmp_path / "fault-origin.json"
    origin.write_text(json.dumps({"lease_wall": time.time() - 0.25}))
    assert time.monotonic() - origin_monotonic(str(origin)) == pytest.approx(0.25, abs=0.05)
    origin.write_text(json.dumps({"lease_wall": time.time() - 60.0}))     # not this run's: the arming is t = 0
    assert time.monotonic() - origin_monotonic(str(origin)) == pytest.approx(0.0, abs=0.05)
    assert time.monotonic() - origin_monotonic(None) == pytest.approx(0.0, abs=0.05)
