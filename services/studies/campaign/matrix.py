"""The fault campaign: a matrix of scenarios × faults, each one a `sharedctl demo --fault …` run judged
on the simulator's ground truth, aggregated into one result.

* `plan(quick)` — the matrix (`Case`s). Quick: every fault family once (≥ 20 runs); full: sweeps
  of operator latency × loss, bursts, blackouts, duplication/reordering/corruption/replay,
  telemetry faults, CAN loss/delay/corruption/bus-off/babble, controller kill and hang (SIGSTOP)
  at several points of the approach to the wall (so some land at speed), console and robot kills.
* `demo_argv(case, json_out, log_dir)` — the command line of one run.
* `run_campaign(cases, runner, …)` — runs them one after another (`runner(case) -> RunResult`;
  `subprocess_runner` in production, a fake in the tests) and calls back after each.
* `judge(case, result, forecasts)` → one row; `aggregate(rows)` → the campaign's JSON.

Every row is judged on the ground truth (violations, min_margin) and against the safety policy
of docs/safety.md: a violation is *documented* only when the run lost actuation (a controller
kill or hang, a CAN bus-off, or an estop) at a moment when the stopping-distance forecast
(stopping.py, on the robot's true plant) says the braking (disarmed) robot leaves the set; any other
violation is *unexpected* (likewise a CAN delay whose torque-loop delay the in-process
forecast puts beyond the measured delay limit), and `aggregate(...)["ok"]` is False.
"""
from __future__ import annotations

import itertools
import json
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from sharedctl.services.summary_output import read_json
from sharedctl.services.summary_output import write_json as write_summary_json

ADVERSARIAL, PAPER = "adversarial_wall", "paper_convex"
DURATION = 5.0                   # s of every run unless the case says otherwise
RUN_TIMEOUT_MARGIN = 90.0        # s on top of the duration before a run is stopped
WATCHDOG = 0.1                   # s, the drives' watchdog
FEEDBACK_TIMEOUT = 0.05          # s, the controller's CAN feedback timeout
ACTUATION_LOSS = ("controller.kill_at", "controller.stop_at", "can.busoff")


@dataclass(frozen=True)
class Case:
    scenario: str
    faults: tuple[str, ...] = ()
    duration: float = DURATION
    controller: str | None = None
    repeat: int = 0                  # a second run of the same case (the baseline's spread)

    @property
    def id(self) -> str:
        law = f"[{self.controller}]" if self.controller else ""
        again = f"#{self.repeat + 1}" if self.repeat else ""
        return f"{self.scenario}{law}|{' '.join(self.faults) or 'none'}|{self.duration:g}s{again}"

    @property
    def family(self) -> str:
        keys = sorted({f.split("=", 1)[0] for f in self.faults if not f.startswith("seed=")})
        if not keys:
            return "none"
        return "+".join(keys)

    def fault_value(self, key: str) -> list[float] | None:
        """The numbers of fault `key` (e.g. controller.stop_at → [SEC, DURATION]), None if absent."""
        for spec in self.faults:
            name, _, value = spec.partition("=")
            if name == key:
                return [float(v.rstrip("%")) / (100.0 if v.endswith("%") else 1.0) for v in value.split(",")]
        return None

    def actuation_loss(self) -> tuple[float, float] | None:
        """(time, hold) of a loss of actuation this case injects: the drives keep the last torque for
        `hold` s and then coast. None if the case injects none (or one too short to trip the watchdog)."""
        for key in ACTUATION_LOSS:
            value = self.fault_value(key)
            if value is None:
                continue
            if key == "controller.kill_at":
                return value[0], WATCHDOG
            if key == "controller.stop_at" and value[1] > WATCHDOG:
                return value[0], WATCHDOG
            if key == "can.busoff" and value[1] > FEEDBACK_TIMEOUT:
                return value[0], WATCHDOG
        return None

    def fault_time(self) -> float | None:
        """When the earliest timed fault (a process fault, a bus-off, a blackout) lands; None if none is timed."""
        times = [v[0] for spec in self.faults for key in (spec.partition("=")[0],)
                 if key.endswith(("kill_at", "stop_at", ".busoff", ".blackout")) for v in [self.fault_value(key)] if v]
        return min(times) if times else None

    def short_hang(self) -> tuple[float, float] | None:
        """(START, DURATION) of a controller hang too short to trip the watchdog (a transient loop delay)."""
        value = self.fault_value("controller.stop_at")
        return (value[0], value[1]) if value and value[1] <= WATCHDOG else None

    def loop_delay(self) -> float | None:
        """s added to the torque loop by a CAN delay (the gateway delays both directions), None if none."""
        value = self.fault_value("can.delay_ms")
        return 2.0 * value[0] / 1000.0 if value and value[0] > 0 else None


@dataclass
class RunResult:
    summary: dict | None          # the demo's JSON, None if it wrote none
    exit_code: int | None
    wall_seconds: float
    error: str | None = None
    summary_file: str | None = None
    log_dir: Path | None = None      # the run's process logs, if kept


# (process, key of its exit summary, the row's `host` key, scale): the real-time loops' figures a row keeps
_FIGURES = (("robot", "physics_steps", "robot_physics_steps", 1.0),
            ("robot", "missed_ticks", "robot_missed_ticks", 1.0),
            ("robot", "skipped_s", "robot_skipped_s", 1.0),
            ("controller", "missed", "controller_missed_deadlines", 1.0),
            ("controller", "jitter_max_us", "controller_jitter_max_ms", 1e-3),
            ("controller", "estops", "controller_estops", 1.0))


OVERLOAD_MISSED_FRACTION = 0.5   # the robot's loop missed more than half its physics ticks


def overloaded(host: dict | None) -> bool:
    """The run's robot simulator could not keep real time (see docs/safety.md §3)."""
    if not host or not host.get("robot_physics_steps"):
        return False
    return host.get("robot_missed_ticks", 0) / host["robot_physics_steps"] > OVERLOAD_MISSED_FRACTION


def host_figures(log_dir: Path | None, demo: dict | None = None) -> dict | None:
    """How far the robot's and the controller's real-time loops fell behind, from their exit summaries: the
    ones the demo's JSON holds (`processes.<name>.summary`), else the JSON files they wrote in the run's log
    directory (`<name>.json`). None if there are none."""
    processes = (demo or {}).get("processes") or {}
    summaries = {}
    for name in ("robot", "controller"):
        summary = (processes.get(name) or {}).get("summary")
        if summary is None and log_dir is not None:
            summary = read_json(Path(log_dir) / f"{name}.json")
        summaries[name] = summary or {}
    out = {}
    for name, key, figure, scale in _FIGURES:
        value = summaries[name].get(key)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            out[figure] = float(value) * scale
    return out or None


# ----- the matrix ------------------------------------------------------------------------
def _cases(scenario, faults_list, duration=DURATION, controller=None):
    return [Case(scenario, tuple(f), duration, controller) for f in faults_list]


def plan(quick: bool = False) -> list[Case]:
    """The campaign's cases, interleaved by family so a shortened campaign still covers every family."""
    A, P = ADVERSARIAL, PAPER
    families: dict[str, list[Case]] = {}

    def add(name, cases):
        families.setdefault(name, []).extend(cases)

    if quick:   # 20 short runs; several faults share a run where they act on different things
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
    add("can-delay", _cases(A, [[f"can.delay_ms={d:g}"] for d in (0.5, 1, 2, 3, 4, 5, 6, 7, 8, 10)])
        + _cases(P, [[f"can.delay_ms={d:g}"] for d in (2, 5, 10)]))
    add("can-mixed", _cases(A, [[f"can.loss={loss:g}", f"can.delay_ms={d:g}"] for loss in (0.05, 0.2)
                                for d in (2, 5, 10)])
        + _cases(A, [["can.jitter_ms=2"], ["can.ids=feedback", "can.loss=0.2"], ["can.ids=command", "can.loss=0.2"],
                     ["can.duplicate=0.2"], ["can.reorder=0.1,2"]]))
    add("can-corrupt", _cases(A, [["can.corrupt=0.01"], ["can.corrupt=0.05"]]) + _cases(P, [["can.corrupt=0.05"]]))
    add("can-busoff", _cases(A, [[f"can.busoff={s:g},{d:g}"] for s in (0.5, 1.0, 1.9, 3.5) for d in (0.03, 0.3, 1.0)])
        + _cases(P, [[f"can.busoff=2,{d:g}"] for d in (0.03, 0.3)]))
    add("can-babble", _cases(A, [["can.babble=1000"], ["can.babble=4000,0x000,1.0,2.0"]])
        + _cases(P, [["can.babble=2000"]]))
    kills = (0.25, 0.5, 0.75, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.75, 1.9, 2.1, 2.3, 3.0, 3.5, 4.0)
    add("controller-kill", _cases(A, [[f"controller.kill_at={t:g}"] for t in kills])
        + _cases(P, [[f"controller.kill_at={t:g}"] for t in (1.0, 2.5, 4.0)]))
    add("controller-hang", _cases(A, [[f"controller.stop_at={t:g},{d:g}"] for t in (0.5, 1.0, 1.5, 1.9, 2.2, 3.5)
                                      for d in (0.05, 0.3, 1.0)])
        + _cases(P, [[f"controller.stop_at=2,{d:g}"] for d in (0.05, 0.3, 1.0)]))
    add("console-kill", _cases(A, [[f"console.kill_at={t:g}"] for t in (0.5, 1.0, 1.5, 2.0, 3.0)])
        + _cases(P, [[f"console.kill_at={t:g}"] for t in (1.0, 3.0)]))
    add("robot-kill", _cases(A, [["robot.kill_at=1.0"], ["robot.kill_at=2.0"], ["robot.kill_at=3.0"]])
        + _cases(P, [["robot.kill_at=2.0"]]))
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
    argv = [sys.executable, "-m", "sharedctl.services.cli", "demo", "--scenario", case.scenario,
            "--duration", f"{case.duration:g}", "--headless", "--no-reference", "--json", str(json_out)]
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


# ----- judging -------------------------------------------------------------------------------
def _estop_times(summary: dict) -> list[float]:
    return [e["t"] for e in summary.get("event_log", []) if e.get("kind") == "estop"]


def judge(case: Case, result: RunResult, forecasts=None) -> dict:
    """One row of the campaign: ground-truth verdict, the fault's forecast, and whether the row is
    within the documented policy (`documented`: a violation explained by a loss of actuation)."""
    s = result.summary or {}
    truth = s.get("truth_samples", 0) or 0
    violations = int(s.get("violations", 0) or 0)
    estops = int(s.get("estops", 0) or 0)
    loss = case.actuation_loss()
    forecast = forecasts.coast(case.scenario, case.duration, case.controller, *loss) if (forecasts and loss) else None
    lag, hang = case.loop_delay(), case.short_hang()
    delayed = None
    if forecasts and (lag or hang):
        delayed = forecasts.delay(case.scenario, case.duration, case.controller, lag or 0.0, hang)
    first = s.get("first_violation_t")
    estop_first = [t for t in _estop_times(s) if first is not None and t <= first]
    host = host_figures(result.log_dir, result.summary)
    # an estop the demo's observer did not see (before it connected) still shows in the controller's count
    estops = max(estops, int((host or {}).get("controller_estops", 0)))
    # an estop before the run's start, or before a timed fault lands: the fault met a robot already stopping
    landing = max(case.fault_time() or 0.0, 0.0)
    early = [t for t in _estop_times(s) if t < landing] or (estops and not _estop_times(s))
    if result.summary is None or truth == 0:
        outcome = "error"
    elif early and not violations:
        outcome = "not exercised"
    elif violations:
        outcome = "violation"
    elif estops:
        outcome = "estop"
    else:
        outcome = "safe"
    explained = None
    if violations:
        if forecast is not None and forecast["worst_min_margin"] < 0.0:
            explained = (f"actuation lost at {forecast['approach_speed']:.2f} m/s toward a face "
                         f"{forecast['margin']:.2f} m away: the disarmed robot cannot stop short of it (forecast)")
        elif delayed is not None and delayed["worst_min_margin"] < 0.0:
            what = (f"torque loop delayed by {1e3 * lag:.0f} ms or more" if lag else
                    f"controller hung {1e3 * hang[1]:.0f} ms at {hang[0]:g} s (torque held)")
            explained = (f"{what}: beyond the measured delay limit "
                         f"(in-process margin {delayed['worst_min_margin']:.3f} m)")
        else:
            reasons = []
            if overloaded(host):
                reasons.append(f"host overloaded: the robot's real-time loop missed {host['robot_missed_ticks']:.0f} "
                               f"of {host['robot_physics_steps']:.0f} ticks (stalls caught up with the torque held: a "
                               f"torque-loop delay beyond the limit of docs/safety.md §3)")
            if estop_first:
                reasons.append(f"estop at {estop_first[0]:.2f} s before the first violation: "
                               "a braked stop too long for the margin")
            explained = "; ".join(reasons) or None
    min_margin = s.get("min_margin")
    return {
        "id": case.id, "scenario": case.scenario, "controller": case.controller, "law": s.get("controller"),
        "faults": list(case.faults), "family": case.family, "duration": case.duration,
        "outcome": outcome, "violations": violations,
        "min_margin": float(min_margin) if isinstance(min_margin, (int, float)) else None,
        "min_margin_t": s.get("min_margin_t"), "first_violation_t": first,
        "estops": estops, "estop_times": _estop_times(s), "final_speed": s.get("final_speed"), "truth_samples": truth,
        "injected": s.get("injected"), "fault_config": s.get("faults"),
        "failure": s.get("failure"), "demo_ok": s.get("ok"), "exit_code": result.exit_code,
        "wall_seconds": round(result.wall_seconds, 2), "error": result.error, "summary_file": result.summary_file,
        "host": host,
        "forecast": forecast, "delay_forecast": delayed, "explained": explained,
        "documented": violations == 0 or explained is not None,
    }


def aggregate(rows: list[dict], meta: dict | None = None) -> dict:
    """The campaign's JSON: counts, the worst margin, the families, and every row."""
    margins = [r["min_margin"] for r in rows if r["min_margin"] is not None and math.isfinite(r["min_margin"])
               and r["outcome"] not in ("error", "not exercised")]
    families: dict[str, dict] = {}
    for r in rows:
        f = families.setdefault(r["family"], {"runs": 0, "violating_runs": 0, "estop_runs": 0, "errors": 0,
                                              "not_exercised": 0, "min_margin": None})
        f["runs"] += 1
        f["violating_runs"] += r["violations"] > 0
        f["estop_runs"] += r["estops"] > 0
        f["errors"] += r["outcome"] == "error"
        f["not_exercised"] += r["outcome"] == "not exercised"
        if r["min_margin"] is not None and r["outcome"] not in ("error", "not exercised"):
            f["min_margin"] = r["min_margin"] if f["min_margin"] is None else min(f["min_margin"], r["min_margin"])
    unexpected = [r["id"] for r in rows if not r["documented"]]
    overload = [r["id"] for r in rows if r["violations"] and "host overloaded" in (r["explained"] or "")]
    idle = [r["id"] for r in rows if r["outcome"] == "not exercised"]
    errors = [r["id"] for r in rows if r["outcome"] == "error"]
    return {
        **(meta or {}),
        "runs": len(rows),
        "violations": sum(r["violations"] for r in rows),
        "violating_runs": sum(1 for r in rows if r["violations"]),
        "documented_violating_runs": sum(1 for r in rows if r["violations"] and r["documented"]),
        "unexpected_violations": unexpected,
        "overload_violations": overload,
        "overloaded_runs": sum(1 for r in rows if overloaded(r.get("host"))),
        "errors": errors,
        "estop_runs": sum(1 for r in rows if r["estops"]),
        "not_exercised": idle,
        "min_margin": min(margins) if margins else None,
        "wall_seconds": round(sum(r["wall_seconds"] for r in rows), 1),
        "families": families,
        "ok": not unexpected,
        "rows": rows,
    }


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


def write_json(path: Path, result: dict) -> None:
    """The campaign's JSON (summary_output.write_json: atomic, non-finite numbers as null)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_summary_json(path, result, indent=1, default=str)
