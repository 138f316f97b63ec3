"""The fault campaign: a matrix of scenarios × faults, each one a `sharedctl demo --fault …` run judged
on the simulator's ground truth (judge.py), aggregated into one result.

* `plan(quick)` — the matrix (`Case`s). Quick: every fault family once (≥ 20 runs); full: sweeps
  of operator latency × loss, bursts, blackouts, duplication/reordering/corruption/replay,
  telemetry faults, CAN loss/delay/corruption/bus-off/babble up to the envelope (25 ms each way
  with 20 % loss), and on the adversarial wall a controller kill, a controller hang of T_w/2, of
  T_w less five periods (the controller resumes before the drives' watchdog) and of T_w (it does
  not), and an operator's estop at every 0.1 s of the approach to the wall (APPROACH), longer
  hangs, console and robot kills; intruders and bad days (docs/security.md): a controller killed
  and restarted (it must resume disarmed), a drive that restarts, another CAN master, a command
  flood, a replay after a flood of sessions, and — behind the `--secure` router — the router
  restarted and the other faults met by the secured stack; the paper scenario samples each family.
  A step of the wall clock is not a family: it would step the host's clock under every other
  process; its mitigation takes the wall clock out of the decision (tests/services).
* `demo_argv(case, json_out, log_dir)` — the command line of one run.
* `run_campaign(cases, runner, …)` — runs them one after another (`runner(case) -> RunResult`;
  `subprocess_runner` in production, a fake in the tests) and judges each (judge.py).

Every time in a fault is on the run's clock: t = 0 is the instant the operator was granted the
lease, as the controller reports it (services/faults/stack.py).
"""
from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from sharedctl.services.children import python_module

from .judge import CONTROL_PERIOD, ESTOP_HOLDS, FEEDBACK_TIMEOUT, WATCHDOG, WATCHDOG_HOLDS, RunResult, judge

ADVERSARIAL, PAPER = "adversarial_wall", "paper_convex"
DURATION = 5.0                   # s of every run unless the case says otherwise
RUN_TIMEOUT_MARGIN = 90.0        # s on top of the duration before a run is stopped
ACTUATION_LOSS = ("controller.kill_at", "controller.stop_at", "can.busoff", "operator.estop_at")
TIMED = ("kill_at", "stop_at", "estop_at", ".busoff", ".blackout", "reboot_at", "intruder_at", "flood_at",
         "evict_at", "restart_at")
# The adversarial wall's approach, on the run's clock (s): from the instant the wall becomes the nearest
# face, the robot at 1.0 m/s (1.45 s in the sampled loop on the robot's plant), past its rest at the band
# (2.73 s), with the face within the stopping distance from the peak approach speed, D(1.28 m/s) = 0.40 m,
# from 2.13 s (stopping.approach_window; tests/studies/test_campaign.py checks the instants still cover it)
APPROACH = tuple(round(1.5 + 0.1 * k, 1) for k in range(16))       # 1.5, 1.6, …, 3.0
ENVELOPE_CAN_DELAY_MS, ENVELOPE_CAN_LOSS = 25.0, 0.2                 # each way; the guarantee's CAN envelope


@dataclass(frozen=True)
class Case:
    scenario: str
    faults: tuple[str, ...] = ()
    duration: float = DURATION
    controller: str | None = None
    repeat: int = 0                  # a second run of the same case (the baseline's spread)
    secure: bool = False             # behind the --secure router (usrpwd, mTLS, ACL)

    @property
    def id(self) -> str:
        law = f"[{self.controller}]" if self.controller else ""
        again = f"#{self.repeat + 1}" if self.repeat else ""
        secure = "[secure]" if self.secure else ""
        return f"{self.scenario}{law}{secure}|{' '.join(self.faults) or 'none'}|{self.duration:g}s{again}"

    @property
    def family(self) -> str:
        keys = sorted({f.split("=", 1)[0] for f in self.faults if not f.startswith("seed=")})
        name = "+".join(keys) if keys else "none"
        return f"secure:{name}" if self.secure else name

    def fault_value(self, key: str) -> list[float] | None:
        """The numbers of fault `key` (e.g. controller.stop_at → [SEC, DURATION]), None if absent."""
        for spec in self.faults:
            name, _, value = spec.partition("=")
            if name == key:
                return [float(v.rstrip("%")) / (100.0 if v.endswith("%") else 1.0) for v in value.split(",")]
        return None

    def actuation_loss(self) -> tuple[str, float, tuple[float, ...]] | None:
        """(fault key, planned time, holds) of a loss of actuation this case injects: the drives keep the
        last torque for one of `holds` s (not known better) and then brake. None if the case injects none
        (or one the drives never see: a bus-off shorter than the feedback timeout, a hang shorter than
        T_w less two periods)."""
        for key in ACTUATION_LOSS:
            value = self.fault_value(key)
            if value is None:
                continue
            if key == "controller.kill_at":
                return key, value[0], WATCHDOG_HOLDS
            if key == "controller.stop_at" and value[1] >= WATCHDOG - 2 * CONTROL_PERIOD:
                return key, value[0], tuple(min(h, value[1]) for h in WATCHDOG_HOLDS)
            if key == "can.busoff" and value[1] > FEEDBACK_TIMEOUT:
                return key, value[0], WATCHDOG_HOLDS
            if key == "operator.estop_at":
                return key, value[0], ESTOP_HOLDS
        return None

    def injected_estop(self) -> float | None:
        value = self.fault_value("operator.estop_at")
        return value[0] if value else None

    def has_can_faults(self) -> bool:
        return any(f.startswith("can.") for f in self.faults)

    def fault_time(self) -> float | None:
        """When the earliest timed fault (a process fault, a bus-off, a blackout) lands; None if none is timed."""
        times = [v[0] for spec in self.faults for key in (spec.partition("=")[0],)
                 if key.endswith(TIMED) for v in [self.fault_value(key)] if v]
        return min(times) if times else None

    def short_hang(self) -> tuple[float, float] | None:
        """(START, DURATION) of a controller hang the controller may resume from before the drives' watchdog
        expires (DURATION ≤ T_w less a period: the last torque frame went out up to a period before the
        stop): the drives hold the torque meanwhile. A hang within two periods of T_w may end either way,
        and `actuation_loss` names it too; one of T_w always trips the watchdog."""
        value = self.fault_value("controller.stop_at")
        return (value[0], value[1]) if value and value[1] <= WATCHDOG - CONTROL_PERIOD + 1e-9 else None

    def loop_delay(self) -> float | None:
        """s added to the torque loop by a CAN delay (the gateway delays both directions), None if none."""
        value = self.fault_value("can.delay_ms")
        return 2.0 * value[0] / 1000.0 if value and value[0] > 0 else None


# ----- the matrix ------------------------------------------------------------------------
def _cases(scenario, faults_list, duration=DURATION, controller=None, secure=False):
    return [Case(scenario, tuple(f), duration, controller, secure=secure) for f in faults_list]


def plan(quick: bool = False) -> list[Case]:
    """The campaign's cases, interleaved by family so a shortened campaign still covers every family."""
    A, P = ADVERSARIAL, PAPER
    families: dict[str, list[Case]] = {}

    def add(name, cases):
        families.setdefault(name, []).extend(cases)

    if quick:   # 25 short runs; several faults share a run where they act on different things
        q = 4.0
        add("none", _cases(A, [()], q) + _cases(P, [()], q))
        add("operator", _cases(A, [["operator.delay_ms=300"], ["operator.loss=0.3", "operator.burst=0.2,0.2"],
                                   ["operator.duplicate=0.5", "operator.reorder=0.3"],
                                   ["operator.corrupt=0.2", "operator.replay=0.3"]], q)
            + _cases(A, [["operator.blackout=0.5,5"]], 5.0)
            + _cases(P, [["operator.delay_ms=1000", "operator.loss=0.5"]], q))
        add("telemetry", _cases(A, [["telemetry.delay_ms=300", "telemetry.loss=0.3"]], q))
        add("can", _cases(A, [["can.loss=0.1"], ["can.delay_ms=5"], ["can.corrupt=0.01"], ["can.busoff=3,0.3"]], q)
            + _cases(P, [["can.babble=2000"]], q))
        add("process", _cases(A, [["controller.kill_at=1.9"], ["controller.kill_at=0.5"], ["controller.stop_at=3,0.5"],
                                  ["console.kill_at=1"], ["robot.kill_at=3"]], q)
            + _cases(P, [["controller.stop_at=2,0.05"]], q))
        add("intruders", _cases(A, [["controller.kill_at=1.9", "controller.restart_at=2.9"], ["robot.reboot_at=2.2"],
                                    ["can.intruder_at=2.2"], ["operator.flood_at=1,2000,1", "operator.evict_at=2.5"]],
                                q))
        add("secure", _cases(A, [["router.restart_at=1.5", "operator.delay_ms=100", "operator.corrupt=0.2"]], q,
                             secure=True))
        return _interleave(families)

    delays = (0, 100, 200, 300, 500, 750, 1000)
    losses = (0.0, 0.1, 0.3, 0.5, 0.8, 1.0)
    add("none", [Case(A, repeat=k) for k in range(2)] + [Case(P, repeat=k) for k in range(2)]
        + _cases(A, [()], controller="nce")
        + _cases(A, [()], controller="of"))
    add("operator-grid", [Case(A, tuple(f for f in (f"operator.delay_ms={d}" if d else "",
                                                    f"operator.loss={loss:g}" if loss else "") if f))
                          for d in delays for loss in losses if d or loss])
    add("operator-grid-paper", [Case(P, tuple(f for f in (f"operator.delay_ms={d}" if d else "",
                                                          f"operator.loss={loss:g}" if loss else "") if f))
                                for d in (0, 300, 1000) for loss in (0.0, 0.5, 0.9) if d or loss])
    add("operator-jitter", _cases(A, [["operator.delay_ms=100", "operator.jitter=pareto:100"],
                                      ["operator.jitter=normal:50"],
                                      ["operator.delay_ms=300", "operator.jitter_ms=200"]]))
    add("operator-burst", _cases(A, [[f"operator.burst={p:g},{r:g}"] for p, r in
                                     ((0.05, 0.5), (0.1, 0.3), (0.2, 0.2), (0.3, 0.1), (0.5, 0.05))])
        + _cases(P, [[f"operator.burst={p:g},{r:g}"] for p, r in ((0.1, 0.3), (0.3, 0.1))]))
    add("operator-blackout", _cases(A, [[f"operator.blackout={s:g},5"] for s in (0.5, 1.0, 1.5, 2.0, 2.3)], 7.5)
        + _cases(P, [[f"operator.blackout={s:g},5"] for s in (1.0, 2.0)], 7.5))
    add("operator-garble", _cases(A, [["operator.duplicate=0.5"], ["operator.duplicate=1.0"], ["operator.reorder=0.3"],
                                      ["operator.reorder=0.5,100"], ["operator.corrupt=0.1"],
                                      ["operator.corrupt=0.5,4"],
                                      ["operator.replay=0.3"], ["operator.replay=0.5,1000"], ["operator.rate=20"]]))
    add("telemetry", _cases(A, [["telemetry.delay_ms=100"], ["telemetry.delay_ms=300"], ["telemetry.delay_ms=500"],
                                ["telemetry.delay_ms=1000"],
                                ["telemetry.loss=0.3"], ["telemetry.loss=0.8"], ["telemetry.loss=1.0"],
                                ["telemetry.blackout=1.0,3"], ["telemetry.burst=0.2,0.2"]]))
    add("can-loss", _cases(A, [[f"can.loss={loss:g}"] for loss in (0.01, 0.02, 0.05, 0.1, 0.15, 0.2)])
        + _cases(P, [[f"can.loss={loss:g}"] for loss in (0.05, 0.1, 0.2)]))
    can_delays = (0.5, 1, 2, 3, 4, 5, 6, 7, 8, 10, 15, 20, ENVELOPE_CAN_DELAY_MS)
    add("can-delay", _cases(A, [[f"can.delay_ms={d:g}"] for d in can_delays])
        + _cases(P, [[f"can.delay_ms={d:g}"] for d in (2, 5, 10, ENVELOPE_CAN_DELAY_MS)]))
    add("can-mixed", _cases(A, [[f"can.loss={loss:g}", f"can.delay_ms={d:g}"] for loss in (0.05, 0.1, ENVELOPE_CAN_LOSS)
                                for d in (2, 5, 10, 15, 20, ENVELOPE_CAN_DELAY_MS)])
        + _cases(P, [[f"can.loss={loss:g}", f"can.delay_ms={d:g}"]
                     for loss, d in ((0.1, 10), (ENVELOPE_CAN_LOSS, ENVELOPE_CAN_DELAY_MS))])
        + _cases(A, [["can.jitter_ms=2"], ["can.ids=feedback", "can.loss=0.2"], ["can.ids=command", "can.loss=0.2"],
                     ["can.duplicate=0.2"], ["can.reorder=0.1,2"]]))
    add("can-corrupt", _cases(A, [["can.corrupt=0.01"], ["can.corrupt=0.05"]]) + _cases(P, [["can.corrupt=0.05"]]))
    add("can-busoff", _cases(A, [[f"can.busoff={s:g},{d:g}"] for s in (0.5, 1.0, 1.9, 3.5) for d in (0.03, 0.3, 1.0)])
        + _cases(P, [[f"can.busoff=2,{d:g}"] for d in (0.03, 0.3)]))
    add("can-babble", _cases(A, [["can.babble=1000"], ["can.babble=4000,0x000,1.0,2.0"]])
        + _cases(P, [["can.babble=2000"]]))
    add("controller-kill", _cases(A, [[f"controller.kill_at={t:g}"] for t in (0.5, 1.0, *APPROACH, 3.5, 4.0)])
        + _cases(P, [[f"controller.kill_at={t:g}"] for t in (1.0, 2.5, 4.0)]))
    # hangs up to T_w: the controller resumes before the watchdog (T_w/2, and T_w less 5 periods), or not (T_w)
    add("controller-hang", _cases(A, [[f"controller.stop_at={t:g},{d:g}"] for t in APPROACH
                                      for d in (WATCHDOG / 2, round(WATCHDOG - 5 * CONTROL_PERIOD, 3), WATCHDOG)])
        + _cases(A, [[f"controller.stop_at={t:g},{d:g}"] for t in (0.5, 1.9, 2.2, 3.5) for d in (0.3, 1.0)])
        + _cases(P, [[f"controller.stop_at=2,{d:g}"] for d in (WATCHDOG / 2, WATCHDOG, 0.3, 1.0)]))
    add("estop", _cases(A, [[f"operator.estop_at={t:g}"] for t in APPROACH])
        + _cases(P, [[f"operator.estop_at={t:g}"] for t in (1.0, 2.5, 4.0)]))
    add("console-kill", _cases(A, [[f"console.kill_at={t:g}"] for t in (0.5, 1.0, 1.5, 2.0, 3.0)])
        + _cases(P, [[f"console.kill_at={t:g}"] for t in (1.0, 3.0)]))
    add("robot-kill", _cases(A, [["robot.kill_at=1.0"], ["robot.kill_at=2.0"], ["robot.kill_at=3.0"]])
        + _cases(P, [["robot.kill_at=2.0"]]))
    # intruders and bad days (docs/security.md): the restarted controller must resume disarmed and stay so (the
    # scripted operator never takes control again); the rest must change nothing or end in a stop inside
    add("controller-restart", _cases(A, [[f"controller.kill_at={t:g}", f"controller.restart_at={t + 1:g}"]
                                         for t in (0.5, 1.5, 2.0, 2.3, 2.6, 3.0)], 6.0)
        + _cases(P, [["controller.kill_at=2.5", "controller.restart_at=3.5"]], 6.0))
    add("drive-reboot", _cases(A, [[f"robot.reboot_at={t:g},{axis}"] for t, axis in
                                   ((0.5, 0), (1.5, 1), (2.2, 2), (2.6, 1), (3.0, 0), (3.5, 1))])
        + _cases(A, [["robot.reboot_at=2.2,1,2"]]) + _cases(P, [["robot.reboot_at=2.5"]]))
    add("can-intruder", _cases(A, [[f"can.intruder_at={t:g}"] for t in (1.0, 2.0, 2.4, 2.8)]
                               + [["can.intruder_at=2.2,1000,2"]]) + _cases(P, [["can.intruder_at=2"]]))
    add("operator-flood", _cases(A, [["operator.flood_at=1,2000,2"], ["operator.flood_at=2.2,5000,1"]])
        + _cases(P, [["operator.flood_at=1,2000,2"]]))
    add("replay-eviction", _cases(A, [["operator.evict_at=1.5"], ["operator.evict_at=2.5"]])
        + _cases(P, [["operator.evict_at=2"]]))
    add("secure", _cases(A, [(), ["router.restart_at=1.5"], ["router.restart_at=2.5,2"],
                             ["controller.kill_at=2.3", "controller.restart_at=3.3"], ["can.intruder_at=2.2"],
                             ["operator.estop_at=2.4"], ["can.delay_ms=10", "can.loss=0.1"],
                             # the link faults, through the relay between the console's router and the site's
                             ["operator.delay_ms=300", "operator.loss=0.3"],
                             ["operator.corrupt=0.2", "operator.replay=0.3", "operator.duplicate=0.3"],
                             ["telemetry.delay_ms=300", "telemetry.loss=0.3"],
                             ["operator.flood_at=1,2000,1", "operator.evict_at=2.5"]], secure=True)
        + _cases(A, [["operator.blackout=1.5,5"]], 7.5, secure=True)
        + _cases(P, [["router.restart_at=2"], ["operator.delay_ms=300", "operator.loss=0.3"]], secure=True))
    add("combined", _cases(A, [["operator.delay_ms=300", "can.loss=0.05"], ["operator.loss=0.5", "can.delay_ms=5"],
                               ["operator.burst=0.2,0.2", "telemetry.delay_ms=300", "can.loss=0.05"],
                               ["operator.delay_ms=500", "console.kill_at=3.0"]])
        + _cases(A, [["operator.delay_ms=300"], ["can.delay_ms=5"]], controller="nce")
        + _cases(A, [["operator.delay_ms=300"], ["can.delay_ms=5"]], controller="of"))
    return _interleave(families)


def _interleave(families: dict[str, list[Case]]) -> list[Case]:
    out, queues = [], [list(v) for v in families.values()]
    while any(queues):
        for q in queues:
            if q:
                out.append(q.pop(0))
    return out


def validate(cases: list[Case], parse) -> dict[str, str]:
    """{case id: reason} for the cases whose faults `parse` (the demo's spec parser) refuses."""
    bad = {}
    for case in cases:
        try:
            parse(list(case.faults))
        except ValueError as exc:
            bad[case.id] = str(exc)
    return bad


# ----- running -----------------------------------------------------------------------------
def demo_argv(case: Case, json_out: Path, log_dir: Path | None = None) -> list[str]:
    argv = [*python_module("sharedctl.services.cli"), "demo", "--scenario", case.scenario,
            "--duration", f"{case.duration:g}", "--headless", "--no-reference", "--json", str(json_out)]
    if case.secure:
        argv.append("--secure")
    if case.controller:
        argv += ["--controller", case.controller]
    if log_dir is not None:
        argv += ["--log-dir", str(log_dir)]
    for spec in case.faults:
        argv += ["--fault", spec]
    return argv


def subprocess_runner(workdir: Path, first_index: int = 0):
    """A runner that starts `sharedctl demo` for a case and reads its JSON; stops it (SIGTERM, then
    SIGKILL — only this process, by PID) if it overruns its duration by RUN_TIMEOUT_MARGIN."""
    counter = itertools.count(first_index)

    def run(case: Case, _position: int) -> RunResult:
        index = next(counter)              # every run, retries included, keeps its own files
        out = workdir / f"run{index:04d}.json"
        logs = workdir / f"run{index:04d}-logs"     # read by host_figures; the workdir goes unless kept
        start = time.monotonic()
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        proc = subprocess.Popen(demo_argv(case, out, logs), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, env=env)
        error = None
        try:
            _, err = proc.communicate(timeout=case.duration + RUN_TIMEOUT_MARGIN)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGTERM)
            try:
                _, err = proc.communicate(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                _, err = proc.communicate()
            error = "timed out"
        wall = time.monotonic() - start
        summary = None
        try:
            summary = json.loads(out.read_text())
        except (OSError, ValueError) as exc:
            tail = (err or b"").decode(errors="replace").strip().splitlines()[-3:]
            error = error or f"no summary ({type(exc).__name__}): {' / '.join(tail)}"
        return RunResult(summary, proc.returncode, wall, error, out.name, logs)
    return run


def run_campaign(cases: list[Case], runner, forecasts=None, on_row=None, should_stop=lambda: False,
                 retries: int = 1) -> list[dict]:
    """Run `cases` in order; `on_row(row, done, total)` after each. Stops early if `should_stop()`.
    A run that was not exercised (estopped before its start: the fault met no motion) is run again,
    at most `retries` times; the row says how many attempts it took."""
    rows = []
    for i, case in enumerate(cases):
        if should_stop():
            break
        for attempt in range(retries + 1):
            row = judge(case, runner(case, i), forecasts)
            row["attempts"] = attempt + 1
            if row["outcome"] != "not exercised" or should_stop():
                break
        rows.append(row)
        if on_row is not None:
            on_row(row, i + 1, len(cases))
    return rows


def rejudge(rows: list[dict], logs: Path, forecasts=None) -> list[dict]:
    """Judge again the runs of an earlier campaign from their kept demo summaries (`--keep-logs`)."""
    out = []
    for i, row in enumerate(rows):
        case = Case(row["scenario"], tuple(row["faults"]), row["duration"],
                    row["controller"] if row["controller"] in ("nce", "of") else None,
                    int(row["id"].rpartition("#")[2]) - 1 if "#" in row["id"] else 0)
        path = logs / (row.get("summary_file") or f"run{i:04d}.json")
        try:
            summary = json.loads(path.read_text())
        except (OSError, ValueError):
            summary = None
        out.append(judge(case, RunResult(summary, row["exit_code"], row["wall_seconds"], row["error"], path.name,
                                         logs / f"{path.stem}-logs"), forecasts))
    return out
