"""A recording as arrays: the controller's telemetry as a simulator ``Trace``, ground truth, link health, rates.

Everything is put on one time axis, the recorder's log time in seconds from the first recorded
message, so telemetry, operator commands, ground truth and events line up whatever clock their
senders used. RobotState gives q, q̂̇, the projected reference q_r, u_h/u_f/u_s, wheel torques,
θ̂, k_h/k_f, authority, the active group's set class and the margin; the operator's wish q_d is
the latest OperatorCommand at each telemetry sample (held); GroundTruth is kept as it is. The
machine law's role is not on the wire, so the figures' "law" band stays empty.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sharedctl.simulator import Trace

from .flight_recorder import METADATA_RUN, METADATA_SCENARIO
from .mcap_reading import ReadStatus, RecordingReader, check_readable

AUTHORITY_CODE = {"human": 0, "shared": 1, "machine": 2}
SET_CLASS_CODE = {"safe": 0, "hysteresis": 1, "hazard": 2}
LINK_FIELDS = ("operator_latency_ms", "loss_fraction", "staleness_ms", "can_feedback_age_ms")


@dataclass
class RecordedRun:
    """What the figures need from one recording."""

    metadata: dict[str, dict[str, str]]
    status: ReadStatus
    trace: Trace | None                       # on the RobotState timeline; None without telemetry
    truth_t: np.ndarray
    truth_q: np.ndarray
    link_t: np.ndarray
    link: dict[str, np.ndarray]
    topic_times: dict[str, np.ndarray]        # log times (s) of every message, per topic
    events: list[tuple[float, str, str, str]] = field(default_factory=list)   # (t, kind, severity, text)

    @property
    def scenario_toml(self) -> str:
        return self.metadata.get(METADATA_SCENARIO, {}).get("toml", "")

    @property
    def title(self) -> str:
        run, scenario = self.metadata.get(METADATA_RUN, {}), self.metadata.get(METADATA_SCENARIO, {})
        return " · ".join(x for x in (scenario.get("name"), run.get("role"), run.get("robot_id"),
                                      run.get("started_utc")) if x)


def _array(rows: list, width: int | None = None) -> np.ndarray:
    if not rows:
        return np.zeros((0, width or 0))
    return np.asarray(rows, dtype=float)


def _set_class(state: dict) -> int:
    classes = [SET_CLASS_CODE.get(c, 0) for c in state["group_classes"]]
    active = state.get("active_group")
    if active is not None and 0 <= active < len(classes):
        return classes[active]
    return min(classes) if classes else -1


def _checked_state(body: dict) -> dict:
    """A RobotState body with every field the trace reads (KeyError/TypeError otherwise)."""
    for name in ("q", "qd_hat", "q_ref", "u_h", "u_f", "u_s", "wheel_torques", "theta_hat"):
        body[name] = [float(x) for x in body[name]]
    for name in ("k_h", "k_f", "min_margin"):
        body[name] = float(body[name])
    body["link"] = {name: float(body["link"][name]) for name in LINK_FIELDS}
    list(body["group_classes"]), str(body["authority"])
    return body


def load_run(path: Path | str) -> RecordedRun:
    """Read a recording (complete or cut short) into arrays."""
    reader = RecordingReader(path)
    states, commands, truth, events = [], [], [], []
    topic_times: dict[str, list[float]] = {}
    t0 = None
    for message in reader.messages():
        if message.view:              # drawn from the messages below: nothing of its own to plot
            continue
        t0 = message.log_time if t0 is None else t0
        t = (message.log_time - t0) / 1e9
        topic_times.setdefault(message.topic, []).append(t)
        if message.undecoded:
            continue
        try:
            body = message.json()
            kind = body.get("type")
            if kind == "robot_state":
                states.append((t, _checked_state(body)))
            elif kind == "operator_command":
                commands.append((t, [float(x) for x in body["q_d"]]))
            elif kind == "ground_truth":
                truth.append((t, [float(x) for x in body["q"]]))
            elif kind == "event":
                events.append((t, str(body["kind"]), str(body["severity"]), str(body["text"])))
        except (ValueError, KeyError, TypeError, AttributeError):   # not a sharedctl message: leave it out
            continue
    check_readable(reader.status, path)
    trace = _trace(states, commands) if states else None
    link_t = np.array([t for t, _ in states])
    link = {name: np.array([s["link"][name] for _, s in states], dtype=float) for name in LINK_FIELDS}
    return RecordedRun(
        metadata=dict(reader.status.metadata), status=reader.status, trace=trace,
        truth_t=np.array([t for t, _ in truth]), truth_q=_array([q for _, q in truth]),
        link_t=link_t, link=link, topic_times={k: np.array(v) for k, v in topic_times.items()}, events=events)


def _trace(states: list[tuple[float, dict]], commands: list[tuple[float, list]]) -> Trace:
    t = np.array([t for t, _ in states])
    col = lambda name: _array([s[name] for _, s in states])   # noqa: E731 — one column of the states, by name
    n = len(states[0][1]["q"])
    q_d = np.full((len(t), n), np.nan)
    if commands:
        command_t = np.array([c for c, _ in commands])
        wish = _array([q for _, q in commands])
        latest = np.searchsorted(command_t, t, side="right") - 1
        have = latest >= 0
        q_d[have] = wish[latest[have]]
    authority = np.array([AUTHORITY_CODE.get(s["authority"], 0) for _, s in states], dtype=int)
    margin = np.array([s["min_margin"] for _, s in states], dtype=float)
    q = col("q")
    return Trace(
        t=t, q=q, v=col("qd_hat"), v_hat=col("qd_hat"), q_d=q_d, q_r=col("q_ref"),
        u_h=col("u_h"), u_f=col("u_f"), u_s=col("u_s"), tau=col("wheel_torques"), theta_hat=col("theta_hat"),
        authority=authority,
        set_class=np.array([_set_class(s) for _, s in states], dtype=int),
        group=np.array([-1 if s.get("active_group") is None else s["active_group"] for _, s in states], dtype=int),
        role=np.full(len(t), -1, dtype=int),
        k_h=col("k_h"), k_f=col("k_f"), intent=np.full(len(t), np.nan), margin=margin,
        inside=margin >= 0.0, finite=bool(np.all(np.isfinite(q))),
        switches=int(np.count_nonzero(np.diff(authority))), group_switches=0,
    )
