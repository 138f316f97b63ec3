"""Controller telemetry: the `RobotState` it publishes, and rate-limited `Event`s.

Pure apart from the caller's clock values: builds wire messages from the control core's
`StepOutput` and the daemon's link measurements.

RobotState field mapping (see the daemon's docstring for where each value comes from):
  q, qd_hat       odometry pose; the velocity the controller used (q̇ from the wheels, or
                  the observer's v̂ for output feedback)
  q_ref           StepOutput.q_r (the projected reference of the active group, or of the group
                  the machine would pick); q when the core has none (NaN)
  group_classes   one class per constraint group, `sharedctl.sets.classify_groups` (classify_rows
                  on that group's rows x = K_g q + T_g, ẋ = K_g q̇; first 16 groups)
  active_group    StepOutput.group (None while the operator has authority)
  authority       core `Authority` → wire `Authority` by name; k_s = 1 if HUMAN else 0
  k_h, k_f        StepOutput.k_h, k_f
  u_h, u_f, u_s   StepOutput (u_s is what was applied: zeros while arming or in estop)
  wheel_torques   τ actually sent (after the torque-limit scaling)
  theta_hat       StepOutput.theta_estimate (the scenario's θ̂0 before the first step)
  min_margin      FeasibleSet.margin(q), the largest of region_margins = FeasibleSet.region_margins(q)
                  (both clipped to ±1e12)
  lease_holder    operator_id holding the authority lease (lease.py), None while it is free
  lease_since     when that holder was granted the lease, on the clock of `time` (wall), None while free:
                  the run's t = 0 for the fault campaign (services/faults/stack.py)
  link            latency from send_time, loss from seq gaps, staleness, oldest wheel feedback age,
                  rejected_messages (every refused operator command and lease request)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sharedctl.protocol.messages import Authority as WireAuthority
from sharedctl.protocol.messages import Event, EventKind, LinkHealth, RobotState, Severity
from sharedctl.protocol.messages import SetClass as WireSetClass
from sharedctl.protocol.wire_types import MAX_GROUPS, MAX_REGIONS, MAX_TEXT_LEN
from sharedctl.sets import SetClass, classify_groups
from sharedctl.short_vectors import all_finite
from sharedctl.sharing import Authority

MAX_MS = 1.0e9   # a bound for "never" in the millisecond link fields (the wire needs finite values)
MAX_MARGIN = 1.0e12     # the bound of the margin fields
WIRE_CLASS = {c: WireSetClass[c.name] for c in SetClass}


def group_classes(feasible, bands, q, v, rows=None) -> tuple[WireSetClass, ...]:
    """Per-group class of the first MAX_GROUPS groups: `classify_groups` (classify_rows on each
    group's rows x = K q + T, ẋ = K v). `rows`: feasible.row_values(q, v), if known."""
    return tuple(WIRE_CLASS[c] for c in classify_groups(feasible, q, v, bands, rows)[:MAX_GROUPS])


def _finite(values, fallback) -> tuple[float, ...]:
    """`values` as floats if it has the shape of `fallback` and is finite, else `fallback` as floats."""
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 1 and arr.shape == np.shape(fallback):
        items = arr.tolist()
        if all_finite(items):
            return tuple(items)
    if arr.shape != np.shape(fallback) or not np.all(np.isfinite(arr)):
        arr = np.asarray(fallback, dtype=float)
    return tuple(float(x) for x in arr)


def _clip_margin(margin: float) -> float:
    """`margin` within ±MAX_MARGIN (NaN stays NaN, as with np.clip)."""
    return -MAX_MARGIN if margin < -MAX_MARGIN else MAX_MARGIN if margin > MAX_MARGIN else margin


def _ms(seconds: float) -> float:
    return MAX_MS if not math.isfinite(seconds) else float(min(max(seconds * 1e3, 0.0), MAX_MS))


@dataclass(frozen=True)
class Link:
    latency: float          # s
    loss_fraction: float
    staleness: float        # s (inf: never heard)
    can_feedback_age: float  # s (inf: never heard)
    rejected: int = 0        # operator messages refused since start (commands and lease requests)


def robot_state(
    seq: int, time: float, q, v, out, feasible, bands, wheel_torques, u_s, estop_active: bool,
    lease_holder: str | None, link: Link, theta_hat, lease_since: float | None = None,
) -> RobotState:
    """A `RobotState` from the last `StepOutput` (`out`) and what the daemon measured."""
    n = len(q)
    zeros = np.zeros(n)
    q_array, v_array = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
    if q_array.shape != (feasible.n,) or v_array.shape != (feasible.n,):
        raise ValueError(f"q and v need {feasible.n} entries each, got shapes {q_array.shape} and {v_array.shape}")
    rows = feasible.row_values(q_array.tolist(), v_array.tolist())
    margins = feasible.region_margins(q_array).tolist()     # numpy's K q + T: `rows` may differ in a zero's sign
    authority = out.authority if out is not None else Authority.HUMAN
    group = out.group if out is not None and out.group is not None and out.group < MAX_GROUPS else None
    return RobotState(
        seq=seq, time=max(time, 0.0), q=_finite(q, zeros), qd_hat=_finite(v, zeros),
        q_ref=_finite(out.q_r if out is not None else q, q),
        group_classes=group_classes(feasible, bands, q_array, v_array, rows),
        active_group=group, authority=WireAuthority[authority.name],
        k_s=1.0 if authority is Authority.HUMAN else 0.0,
        k_h=float(min(max(out.k_h, 0.0), 1.0)) if out is not None else 1.0,
        k_f=float(min(max(out.k_f, 0.0), 1.0)) if out is not None else 0.0,
        u_h=_finite(out.u_h if out is not None else zeros, zeros),
        u_f=_finite(out.u_f if out is not None else zeros, zeros),
        u_s=_finite(u_s, zeros),
        wheel_torques=_finite(wheel_torques, np.zeros(len(wheel_torques))),
        theta_hat=_finite(theta_hat, np.zeros(len(theta_hat))),
        min_margin=_clip_margin(max(margins)),
        region_margins=tuple(_clip_margin(m) for m in margins[:MAX_REGIONS]),
        estop_active=estop_active, lease_holder=lease_holder,
        link=LinkHealth(
            operator_latency_ms=_ms(link.latency), loss_fraction=float(min(max(link.loss_fraction, 0.0), 1.0)),
            staleness_ms=_ms(link.staleness), can_feedback_age_ms=_ms(link.can_feedback_age),
            rejected_messages=max(int(link.rejected), 0),
        ),
        lease_since=None if lease_since is None or not math.isfinite(lease_since) else max(lease_since, 0.0),
    )


@dataclass
class EventLimiter:
    """At most one event per `interval` seconds per topic; suppressed ones are counted and reported."""

    interval: float = 1.0
    source: str = "controller"
    seq: int = 0
    _last: dict = field(default_factory=dict)
    _suppressed: dict = field(default_factory=dict)

    def make(self, now: float, wall: float, topic: str, kind: str, severity: str, text: str) -> Event | None:
        last = self._last.get(topic)
        if last is not None and now - last < self.interval:
            self._suppressed[topic] = self._suppressed.get(topic, 0) + 1
            return None
        self._last[topic] = now
        skipped = self._suppressed.pop(topic, 0)
        if skipped:
            text = f"{text} (+{skipped} similar suppressed)"
        self.seq += 1
        return Event(
            seq=self.seq, time=max(wall, 0.0), kind=EventKind(kind), severity=Severity(severity),
            source=self.source, text=_clean(text)[:MAX_TEXT_LEN],
        )


def _clean(text: str) -> str:
    return "".join(ch if ch.isprintable() or ch in "\t\n" else "?" for ch in text)
