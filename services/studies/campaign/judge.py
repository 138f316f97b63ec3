"""The fault campaign's judge: one run's demo JSON → one row, and the rows → the campaign's JSON.

A row's verdict is the simulator's ground truth (`violations`: samples outside Q_a; `min_margin`).
A violation is *documented* only when a forecast says it must happen; every other violation is
*unexpected*, and `aggregate(...)["ok"]` is False. The forecasts (stopping.py, on the robot's
true plant; `Forecasts` in command.py computes and caches them):

* a loss of actuation — a controller kill, a hang the drives' watchdog sees (the torque held
  T_w, then the brakes), a CAN bus-off the controller's feedback timeout sees, an estop
  (injected, `operator.estop_at`, or the controller's own) — is forecast from the run's own
  ground truth at the instant it actually happened (`fault_states` in the demo's JSON: the fault's
  firing instant on the run's clock, or the controller's time of its estop), each uncertain
  quantity taken in the robot's favour (stopping.forecast_at); an injected estop's torque acts
  until the controller's own estop (its event's time) plus the Estop frames' transit;
* a hang the controller may resume from before the watchdog expires, and a CAN delay, are
  forecast by the in-process sampled loop with the hang at its actual instant, or with the
  torque loop delayed by the CAN delay (with and without two more periods: the better of the
  two). A hang that may end either way is documented only if both forecasts leave the set.

A host that could not keep real time is reported (`host`: the robot's and the controller's loop
figures, `overloaded`), never an excuse: it does not document a violation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from sharedctl.services.summary_output import read_json
from sharedctl.services.summary_output import write_json as write_summary_json

WATCHDOG = 0.1                   # s, the drives' watchdog T_w (RobotSimConfig.watchdog_timeout, [backup] hold)
FEEDBACK_TIMEOUT = 0.05          # s, the controller's CAN feedback timeout
CONTROL_PERIOD = 0.002           # s, the controller's period
ESTOP_HOLDS = (0.0, 2 * CONTROL_PERIOD)          # s the drives drive on after an estop is asked for
CAN_TRANSIT = 0.001              # s, at most, from the controller's Estop frames to the drives (host-local bus)
WATCHDOG_HOLDS = (WATCHDOG - CONTROL_PERIOD, WATCHDOG)   # the last frame reached them up to a period before


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
            ("controller", "late", "controller_late_ticks", 1.0),
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


# ----- what happened when ------------------------------------------------------------------
def _estop_times(summary: dict) -> list[float]:
    return [e["t"] for e in summary.get("event_log", []) if e.get("kind") == "estop"]


def fault_state(summary: dict, key: str) -> dict | None:
    """The demo's `fault_states` entry of fault `key` (e.g. controller.kill_at, can.busoff, estop): the instant
    it fired on the run's clock (`t`), the ground truth and the reported torques around it."""
    for entry in summary.get("fault_states") or []:
        if entry.get("what", "").partition("=")[0] == key and entry.get("truth"):
            return entry
    return None


def fired(summary: dict) -> dict[str, dict]:
    """{fault: {planned_at, done_at, late_by}} of the process faults the demo carried out (the run's clock)."""
    out = {}
    for p in (summary.get("injected") or {}).get("processes") or []:
        out[p["fault"]] = {k: p.get(k) for k in ("planned_at", "done_at", "late_by", "skipped")}
    return out


def _estop_holds(summary: dict, fired_at: float, default: tuple[float, ...]) -> tuple[float, ...]:
    """How long the drives drove on after an estop asked for at `fired_at`: until the controller's estop (its
    own time of it, the event's `at`), plus the Estop frames' transit; `default` if the controller reported none."""
    for e in summary.get("event_log", []):
        if e.get("kind") == "estop" and e.get("at") is not None and e["at"] >= fired_at - CONTROL_PERIOD:
            lag = max(e["at"] - fired_at, 0.0)
            return (lag, lag + CAN_TRANSIT)
    return default


def _explain_loss(what: str, fc: dict) -> str:
    return (f"{what} at {fc['t_fault']:.3f} s, {fc['approach_speed']:.2f} m/s toward a face {fc['margin']:.3f} m "
            f"away: the stop ends {-fc['min_margin']:.3f} m beyond it even at best (forecast from the ground truth)")


def controller_outcome(summary: dict) -> dict | None:
    """What the (last) controller said of the run: how it started (resumed, declared, refused), its mode at the
    end, the other master's frames it saw, the operator messages it refused by reason; and what the
    intrusions of the run did (the demo's counters)."""
    controller = ((summary.get("processes") or {}).get("controller") or {}).get("summary")
    if not controller:
        return None
    return {"start": controller.get("start"), "mode": controller.get("mode"),
            "arming_refused": controller.get("arming_refused"),
            "foreign_commands": controller.get("foreign_commands"), "rejections": controller.get("rejections"),
            "intrusions": (summary.get("injected") or {}).get("intrusions") or {}}


def judge(case, result: RunResult, forecasts=None) -> dict:
    """One row of the campaign: ground-truth verdict, the forecasts of what the run's faults force, and
    whether a violation is one a forecast says must happen (`documented`)."""
    s = result.summary or {}
    truth = s.get("truth_samples", 0) or 0
    violations = int(s.get("violations", 0) or 0)
    estops = int(s.get("estops", 0) or 0)
    first = s.get("first_violation_t")
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

    forecast = delayed = estop_forecast = None
    loss = case.actuation_loss()
    if forecasts is not None and loss is not None:
        key, _, holds = loss
        state = fault_state(s, key)
        if state is not None:
            if key == "operator.estop_at":
                holds = _estop_holds(s, state["t"], holds)
            forecast = forecasts.coast(case.scenario, case.controller, state, holds)
    lag, hang = case.loop_delay(), case.short_hang()
    if forecasts is not None and (lag or hang):
        if hang is not None:
            state = fault_state(s, "controller.stop_at")
            hang = (state["t"] if state is not None else hang[0], hang[1])
        delayed = forecasts.delay(case.scenario, case.duration, case.controller, lag or 0.0, hang)
    estop_first = [t for t in _estop_times(s) if first is not None and t <= first]
    if forecasts is not None and violations and estop_first and case.injected_estop() is None:
        state = fault_state(s, "estop")
        if state is not None:
            holds = ESTOP_HOLDS + ((WATCHDOG,) if case.has_can_faults() else ())   # a lost Estop frame: the watchdog
            estop_forecast = forecasts.coast(case.scenario, case.controller, state, holds)

    # what the fault may have done, each forecast: documented only if every one of them leaves the set
    reasons = []
    if forecast is not None:
        reasons.append((forecast["min_margin"], _explain_loss(loss[0], forecast)))
    if delayed is not None:
        what = (f"torque loop delayed by {1e3 * lag:.0f} ms or more" if lag else
                f"controller hung {1e3 * hang[1]:.0f} ms at {hang[0]:.3f} s (torque held)")
        reasons.append((delayed["best_min_margin"], f"{what}: the in-process loop leaves the set too "
                                                    f"(margin {delayed['best_min_margin']:.3f} m at best)"))
    explained = None
    if violations and reasons and all(margin < 0.0 for margin, _ in reasons):
        explained = "; ".join(text for _, text in reasons)
    elif violations and estop_forecast is not None and estop_forecast["min_margin"] < 0.0:
        explained = _explain_loss("estop", estop_forecast)
    min_margin = s.get("min_margin")
    return {
        "id": case.id, "scenario": case.scenario, "controller": case.controller, "law": s.get("controller"),
        "faults": list(case.faults), "family": case.family, "duration": case.duration,
        "outcome": outcome, "violations": violations,
        "min_margin": float(min_margin) if isinstance(min_margin, (int, float)) else None,
        "min_margin_t": s.get("min_margin_t"), "first_violation_t": first,
        "estops": estops, "estop_times": _estop_times(s), "final_speed": s.get("final_speed"), "truth_samples": truth,
        "run_clock": s.get("run_clock"), "fired": fired(s),
        "injected": s.get("injected"), "fault_config": s.get("faults"),
        "failure": s.get("failure"), "demo_ok": s.get("ok"), "exit_code": result.exit_code,
        "wall_seconds": round(result.wall_seconds, 2), "error": result.error, "summary_file": result.summary_file,
        "host": host, "overloaded": overloaded(host),
        "forecast": forecast, "estop_forecast": estop_forecast, "delay_forecast": delayed, "explained": explained,
        "controller_outcome": controller_outcome(s),
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
    overload = [r["id"] for r in rows if r["violations"] and overloaded(r.get("host"))]
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


def write_json(path: Path, result: dict) -> None:
    """The campaign's JSON (summary_output.write_json: atomic, non-finite numbers as null)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_summary_json(path, result, indent=1, default=str)
