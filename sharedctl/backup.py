"""Backup-safe states: the fail-safe stop ends inside Q_a (docs/control.md §10).

When the controller is lost (killed, hung, its bus gone) every drive holds its last torque until
its watchdog expires, `hold` = T_w seconds, then disarms and its wheel's fail-safe brake stops the
robot. A state is *backup-safe* when that stop, started now, ends inside the admissible set.

The brakes are described per block of coordinates that share one speed (the omnidirectional
robot: the translation (x, y) and the yaw ψ): whatever the direction of motion, the unpowered
robot's speed |v_b| in block b decreases at least at a_c + k|v_b| (`BrakeBlock`), so its path from
speed s to rest is at most

    s_b(s) = s/k − (a_c/k²) ln(1 + k s/a_c)          (a_c/k²… → s²/(2a_c) as k → 0),

and a row j of a polytope, K_j q + T_j ≤ 0, moves towards its face by at most Σ_b |K_j,b| s_b.

Two checks, both per row of a polytope that contains q (`BackupModel`):

* the **state** (q, v) is backup-safe with margin δ when, for some containing polytope,
  x_j + Σ_b |K_j,b| (|v_b| T_w + s_b(|v_b|)) ≤ −δ for all its rows — the stop from a command that
  does not speed the robot up;
* a **command** u is backup-safe at (q, v) when holding it for T_w (row by row, exactly: constant
  acceleration a = M⁻¹(u − C v − g)) and braking from v + a T_w stays δ inside, and the state one
  control period later (q + v dt + ½a dt², v + a dt) is backup-safe.

A model whose acceleration under a held torque is not constant (the 2-link arm: M(q), C and g(q)
move during the hold) gives `BackupModel.hold_deviation`, a bound (x, y) of how far q and q̇
depart from the constant-acceleration motion over a hold of T (`models/planar_arm_stop.py` for the
arm); then every reach adds ‖K_j‖x to the hold's advance and brakes from speeds y higher, with
every block's deflection taken as π, and the next state's check allows for the period's own
deviation. Without it (the omnidirectional robot: exact) every result is the one above.

`govern` returns the command to send: u itself when it is backup-safe, else the point of the
segment from u to the fallback u_g closest to u that is; when not even u_g is (the state is
outside the envelope: no stop from here ends δ inside), the one of u and u_g whose stop ends
farther inside. u_g decelerates each block along −v_b at
max(a_c + k|v_b| + a_extra, …) — harder than the brakes — or stops it within T_w at low speed; under
u_g the state's backup margin never decreases, so u_g is always available once the state is
backup-safe (docs/control.md §10 for the argument). Pure: no clocks, no I/O.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .models.planar_arm_stop import ArmBounds, ArmHoldDeviation


@dataclass(frozen=True)
class BrakeBlock:
    """Coordinates `axes` sharing one speed; the unpowered deceleration is at least a_c + k·speed."""

    axes: tuple[int, ...]
    coulomb: float          # a_c (units/s²)
    viscous: float          # k (1/s)
    deflection: float = math.pi   # the most the braked velocity turns from its start (rad; π: any)
    creep: float = 0.0            # path added to every stop: a brake that fades near rest (m)
    cone: tuple = field(init=False, repr=False, compare=False)    # (cos, sin) of the deflection

    def __post_init__(self):
        if not (self.coulomb > 0.0 and self.viscous >= 0.0 and math.isfinite(self.coulomb + self.viscous)
                and 0.0 <= self.deflection <= math.pi):
            raise ValueError("a brake block needs a_c > 0 and k >= 0, finite, and a deflection in [0, π]")
        object.__setattr__(self, "cone", (math.cos(self.deflection), math.sin(self.deflection)))

    def advance(self, rows: list, v_block: list) -> list[float]:
        """For every row (its block part K_j,b and that part's norm, `rows` = [(k, |k|), …]), the
        most its value grows while the brakes stop the block from v_block: s_b(|v_b|) times the
        largest cosine between K_j,b and a velocity within `deflection` of v_b (the displacement
        lies in that cone). On Python floats: a few rows, every sample."""
        speed = math.sqrt(_dot(v_block, v_block))
        if speed <= 0.0:
            return [0.0] * len(rows)
        reach = self.distance(speed)
        if self.deflection >= math.pi:
            return [n * reach for _, n in rows]
        # cos(max(angle(K_j,b, v_b) − deflection, 0)), or 0 past a right angle, without acos:
        # with c = cos angle, cos(angle − d) = c cos d + sin angle sin d
        cos_d, sin_d = self.cone
        out = []
        for k, n in rows:
            if n <= 0.0:
                out.append(0.0)
                continue
            cosine = max(-1.0, min(1.0, _dot(k, v_block) / (n * speed)))
            if cosine >= cos_d:
                out.append(n * reach)
                continue
            turned = cosine * cos_d + math.sqrt(1.0 - cosine * cosine) * sin_d
            out.append(n * reach * turned if turned > 0.0 else 0.0)
        return out

    def distance(self, speed: float) -> float:
        """s_b(speed): the longest path from `speed` to rest with the drives disarmed."""
        if speed <= 0.0:
            return 0.0
        a, k = self.coulomb, self.viscous
        if k * speed < 1e-6 * a:
            return speed * speed / (2.0 * a) + self.creep
        return speed / k - (a / (k * k)) * math.log1p(k * speed / a) + self.creep


@dataclass(frozen=True)
class BackupModel:
    """The fail-safe stop: the last command held `hold` s (T_w), then the brakes of `blocks`."""

    hold: float
    blocks: tuple[BrakeBlock, ...]
    margin: float = 0.01                 # δ (m): how far inside the stop must end
    extra_deceleration: float = 1.0      # a_extra: the fallback brakes this much harder than the brakes
    iterations: int = 12                 # govern's most probes between u and u_g
    # (‖v‖, ‖a‖, T) → (x, y): ‖q(t) − q − vt − ½at²‖ ≤ x and ‖q̇(t) − v − at‖ ≤ y for t ≤ T while the torque
    # of acceleration a is held, nondecreasing in each argument; None: the held acceleration is constant
    hold_deviation: object = None

    def __post_init__(self):
        if not (self.hold >= 0.0 and self.margin >= 0.0 and self.extra_deceleration > 0.0):
            raise ValueError("backup: hold >= 0, margin >= 0 and extra_deceleration > 0 are required")

    # ----- reach: how far each row may still move towards its face -------------------------
    def state_reach(self, K, v) -> list[float]:
        """(K_j v)⁺ T_w + Σ_b advance_b for every row of K: the fallback held T_w (it decelerates
        along −v, so a row advances at most (K_j v)⁺ T_w), then the brakes from v."""
        return _state_reach(self, _rows_of(self, K), _as_floats(v))

    def command_reach(self, K, v, a) -> list[float]:
        """Holding the acceleration a for T_w (each row's largest advance, exact for constant a), then
        braking from v + a T_w."""
        return _command_reach(self, _rows_of(self, K), _as_floats(v), _as_floats(a))

    def state_margin(self, feasible, q, v) -> float:
        """max over the polytopes containing q of min_j −(x_j + reach_j): ≥ δ means backup-safe
        (−inf when no polytope contains q)."""
        v = _as_floats(v)
        return self._margin(feasible, q, lambda rows: _state_reach(self, rows, v))

    def command_margin(self, feasible, q, v, a) -> float:
        v, a = _as_floats(v), _as_floats(a)
        return self._margin(feasible, q, lambda rows: _command_reach(self, rows, v, a))

    def _margin(self, feasible, q, reach_of) -> float:
        q = _as_floats(q)
        best = -math.inf
        for rows in _region_rows(self, feasible):
            x = [_dot(k, q) + t for k, t, _ in rows]
            if max(x) < 0.0:
                best = max(best, min(-(xj + rj) for xj, rj in zip(x, reach_of(rows))))
        return best

    def fallback_acceleration(self, v: np.ndarray) -> np.ndarray:
        """a_g: each block decelerated along −v_b at a_c + k|v_b| + a_extra, or stopped within T_w
        when that is gentler (no reversal during the hold)."""
        a = np.zeros_like(v)
        for block in self.blocks:
            axes = list(block.axes)
            speed = _norm(v[axes].tolist())
            if speed <= 0.0:
                continue
            decel = block.coulomb + block.viscous * speed + self.extra_deceleration
            if self.hold > 0.0:
                decel = min(decel, speed / self.hold)
            a[axes] = -decel * v[axes] / speed
        return a


def _state_reach(backup: BackupModel, rows, v, slack: float = 0.0) -> list[float]:
    """BackupModel.state_reach on rows as `_rows_of` gives them and v as floats (with a hold
    deviation: for every velocity within `slack` of v)."""
    if backup.hold_deviation is not None:
        return _deviating_state_reach(backup, rows, v, slack)
    T = backup.hold
    reach = [max(_dot(k, v), 0.0) * T for k, _, _ in rows]
    return _add_braking(backup, rows, v, reach)


def _command_reach(backup: BackupModel, rows, v, a) -> list[float]:
    """BackupModel.command_reach on rows as `_rows_of` gives them and v, a as floats."""
    if backup.hold_deviation is not None:
        return _deviating_command_reach(backup, rows, v, a)
    T = backup.hold
    reach = []
    for k, _, _ in rows:
        advance = _hold_advance(_dot(k, v), _dot(k, a), T)
        reach.append(advance)
    return _add_braking(backup, rows, [vj + aj * T for vj, aj in zip(v, a)], reach)


def _hold_advance(w: float, alpha: float, T: float) -> float:
    """A row's largest advance over [0, T] at rate w and constant acceleration alpha (exact)."""
    advance = max(w * T + 0.5 * alpha * T * T, 0.0)
    if alpha < 0.0 and 0.0 < -w / alpha < T:
        advance = max(advance, -w * w / (2.0 * alpha))
    return advance


def _add_braking(backup: BackupModel, rows, v_end, reach) -> list[float]:
    """reach + each brake block's advance from v_end, row by row."""
    for b, block in enumerate(backup.blocks):
        extra = block.advance([parts[b] for _, _, parts in rows], [v_end[i] for i in block.axes])
        reach = [r + e for r, e in zip(reach, extra)]
    return reach


# ----- a hold that departs from constant acceleration (BackupModel.hold_deviation) ------------
def _deviating_state_reach(backup: BackupModel, rows, v, slack: float) -> list[float]:
    """The state's reach for every velocity v' with ‖v' − v‖ ≤ slack: the fallback u_g held T_w
    (its constant-acceleration part advances a row at most (K_j v')⁺ T_w ≤ ((K_j v)⁺ + ‖K_j‖ slack) T_w,
    its deviation at most ‖K_j‖ x), then the brakes from block speeds |v_b| + slack + y (deflection π);
    (x, y) the deviation of a hold of T_w from speed ‖v‖ + slack at the fallback's largest acceleration."""
    T = backup.hold
    speed = _norm(v) + slack
    dq, dv = backup.hold_deviation(speed, _fallback_size(backup, speed), T)
    reach = [(max(_dot(k, v), 0.0) + _norm(k) * slack) * T + _scaled(_norm(k), dq) for k, _, _ in rows]
    return _add_deviating_braking(backup, rows, v, slack + dv, reach)


def _deviating_command_reach(backup: BackupModel, rows, v, a) -> list[float]:
    """The command's reach: each row's largest advance under the constant acceleration a over T_w,
    plus ‖K_j‖ x; then the brakes from block speeds |v_b + a_b T_w| + y (deflection π)."""
    T = backup.hold
    dq, dv = backup.hold_deviation(_norm(v), _norm(a), T)
    reach = []
    for k, _, _ in rows:
        advance = _hold_advance(_dot(k, v), _dot(k, a), T)
        reach.append(advance + _scaled(_norm(k), dq))
    return _add_deviating_braking(backup, rows, [vj + aj * T for vj, aj in zip(v, a)], dv, reach)


def _add_deviating_braking(backup: BackupModel, rows, v_end, spread: float, reach) -> list[float]:
    """reach + Σ_b |K_j,b| s_b(|v_end,b| + spread): the braked path from any velocity within
    `spread` of v_end, whose direction the deviation leaves free (deflection π)."""
    for b, block in enumerate(backup.blocks):
        path = _braked_path(block, _norm([v_end[i] for i in block.axes]) + spread)
        reach = [r + _scaled(parts[b][1], path) for r, (_, _, parts) in zip(reach, rows)]
    return reach


def _braked_path(block: BrakeBlock, speed: float) -> float:
    """s_b(speed), inf for an unbounded speed (a hold deviation without a bound)."""
    return block.distance(speed) if speed < math.inf else math.inf


def _scaled(norm: float, length: float) -> float:
    """norm · length, 0 for a row with no part here (even when the length is unbounded)."""
    return norm * length if norm > 0.0 else 0.0


def _fallback_size(backup: BackupModel, speed: float) -> float:
    """The largest ‖a_g‖ of `fallback_acceleration` over velocities of norm ≤ speed (each block's
    deceleration grows with its speed, which is at most ‖v‖)."""
    total = 0.0
    for block in backup.blocks:
        decel = block.coulomb + block.viscous * speed + backup.extra_deceleration
        if backup.hold > 0.0:
            decel = min(decel, speed / backup.hold)
        total += decel * decel
    return math.sqrt(total)


@dataclass(frozen=True)
class Governed:
    """What `govern` decided: the command to send and how far it moved from the one asked for."""

    u: np.ndarray
    share: float          # λ ∈ [0, 1]: 0 = the command as asked, 1 = the fallback
    feasible: bool        # False: not even the fallback is backup-safe (it is sent anyway)


def govern(backup: BackupModel, model, feasible, q: np.ndarray, v: np.ndarray, u: np.ndarray,
           dt: float) -> Governed:
    """The backup-safe command closest to u on the segment u → u_g.

    Most samples are far from every face for their speed: a bound that needs only each polytope's
    smallest slack (`_clearly_safe`) accepts u there without the row-by-row reaches. Elsewhere the
    command's merit m(λ) (`_Probe`: its backup margin less δ; ≥ 0 means backup-safe; only the rows
    near a face for the speed are computed exactly) is found at λ = 0 and, when u fails, at λ = 1;
    when u fails and u_g passes, its root is bracketed by regula falsi with
    the Illinois rule (`_root`): the acceleration is affine in the command, so a(λ) = a_u + λ(a_g − a_u)
    costs no model call; the safe end of the bracket is sent."""
    q, v, u = np.asarray(q, float), np.asarray(v, float), np.asarray(u, float)
    q_list, v_list = q.tolist(), v.tolist()
    a_u = model.acceleration(q, v, u).tolist()
    bounds = _block_bounds(backup, v_list, a_u, dt)
    if _clearly_safe(backup, feasible, q_list, bounds) >= backup.margin:
        return Governed(u, 0.0, True)
    probe = _Probe(backup, feasible, q_list, v_list, dt)
    m_u = probe.merit(a_u, bounds)
    if m_u >= 0.0:
        return Governed(u, 0.0, True)
    a_g = backup.fallback_acceleration(v)
    g_list = a_g.tolist()
    m_g = probe.merit(g_list, _block_bounds(backup, v_list, g_list, dt))
    if not m_g >= 0.0:
        # outside the envelope (no stop from here ends δ inside whatever is sent): the one of u and
        # u_g after which the state one period on has the larger backup margin — a law braking at its
        # barrier keeps it above u_g's (that braking is what stops the robot when nothing fails), a law
        # still tracking towards the face does not; u_g never lowers it (§10)
        if _next_margin(backup, feasible, q, v, a_u, dt) >= _next_margin(backup, feasible, q, v, a_g, dt):
            return Governed(u, 0.0, False)
        return Governed(model.inverse_dynamics(q, v, a_g), 1.0, False)
    step = [g - h for g, h in zip(g_list, a_u)]

    def merit(lam: float) -> float:
        a = [h + lam * s for h, s in zip(a_u, step)]
        return probe.merit(a, _block_bounds(backup, v_list, a, dt))

    share = _root(merit, m_u, m_g, backup)
    u_g = model.inverse_dynamics(q, v, a_g)
    return Governed(u + share * (u_g - u), share, True)


def _next_margin(backup: BackupModel, feasible, q: np.ndarray, v: np.ndarray, a, dt: float) -> float:
    """The backup margin of the state one period on under the acceleration a."""
    a = np.asarray(a, float)
    return backup.state_margin(feasible, q + v * dt + 0.5 * a * dt * dt, v + a * dt)


def _root(merit, m_lo: float, m_hi: float, backup: BackupModel) -> float:
    """The least λ ∈ (0, 1] with merit(λ) ≥ 0, from above: regula falsi on the bracket [lo, hi]
    (merit(lo) < 0 ≤ merit(hi)) with the Illinois rule (the end kept twice has its merit halved
    for the next chord), at most `backup.iterations` probes, until hi − lo ≤ 2⁻¹². A chord point
    that is not strictly inside the bracket (a merit of −inf: no polytope contains the state) is
    replaced by the midpoint. Returns hi: it always passes. On the bench's adversarial-wall
    replay it takes 10 probes on average where bisection takes 12, and its λ is within 0.002 of
    the least passing one (a 30-halving oracle). The batched governor
    (sharedctl/batched/backup.py) runs the same arithmetic per robot."""
    lo, hi, f_lo, f_hi, kept = 0.0, 1.0, m_lo, m_hi, 0
    for _ in range(backup.iterations):
        if hi - lo <= _LAMBDA_RESOLUTION:
            break
        lam = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not lo < lam < hi:
            lam = 0.5 * (lo + hi)
        m = merit(lam)
        if m >= 0.0:
            hi, f_hi = lam, m
            f_lo = 0.5 * f_lo if kept < 0 else f_lo
            kept = -1                     # lo kept
        else:
            lo, f_lo = lam, m
            f_hi = 0.5 * f_hi if kept > 0 else f_hi
            kept = 1                      # hi kept
    return hi


class _Probe:
    """One sample's (q, v) for `govern`: the merit of an acceleration a held from it,
    m(a) = min(command margin, the next state's backup margin) − δ.

    Row by row, a row whose crude bound x_j + Σ_b |K_j,b| C_b (`_block_bounds`: it bounds both the
    command's and the next state's advance) is at or below −δ cannot decide the sign: its value is
    taken as that bound, −(x_j + Σ_b |K_j,b| C_b) ≥ δ, and its exact reach is not computed; the
    rows near a face are computed exactly. The merit's sign is exact; its value, where it is ≥ 0,
    may be a lower row's bound. When the command margin fails (< δ), the merit is that margin
    less δ: its sign is all the governor decides on."""

    __slots__ = ("backup", "regions", "q", "v", "dt")

    def __init__(self, backup: BackupModel, feasible, q: list, v: list, dt: float):
        self.backup, self.q, self.v, self.dt = backup, q, v, dt
        self.regions = [(rows, [_dot(k, q) + t for k, t, _ in rows]) for rows in _region_rows(backup, feasible)]

    def merit(self, a: list, bounds: list) -> float:
        backup, q, v, dt = self.backup, self.q, self.v, self.dt
        delta = backup.margin
        crude_of = _crude_rows(bounds)
        command = -math.inf
        split = []
        for rows, x in self.regions:
            crude = crude_of(rows)
            near, far = [], math.inf          # far: the least bound of the rows that cannot decide
            for j, (xj, cj) in enumerate(zip(x, crude)):
                if xj + cj > -delta:
                    near.append(j)
                else:
                    far = min(far, -(xj + cj))
            split.append((rows, near, far))
            if max(x) < 0.0:
                value = far
                if near:
                    reach = _command_reach(backup, [rows[j] for j in near], v, a)
                    value = min(value, min(-(x[j] + r) for j, r in zip(near, reach)))
                command = max(command, value)
        if command < delta:
            return command - delta
        q1 = [qi + vi * dt + 0.5 * ai * dt * dt for qi, vi, ai in zip(q, v, a)]
        v1 = [vi + ai * dt for vi, ai in zip(v, a)]
        if backup.hold_deviation is not None:
            return min(command, self._deviating_state(split, q1, v1, a)) - delta
        state = -math.inf
        for rows, near, far in split:
            x1 = [_dot(rows[j][0], q1) + rows[j][1] for j in near]
            if x1 and max(x1) >= 0.0:
                continue
            value = far
            if near:
                reach = _state_reach(backup, [rows[j] for j in near], v1)
                value = min(value, min(-(xj + r) for xj, r in zip(x1, reach)))
            state = max(state, value)
        return min(command, state) - delta

    def _deviating_state(self, split, q1, v1, a) -> float:
        """The next state's backup margin when the period itself departs from constant acceleration
        by (x, y) = hold_deviation(‖v‖, ‖a‖, dt): every row value x_j ≤ K_j q1 + T_j + ‖K_j‖x and every
        velocity within y of v1. A polytope counts only when it contains every such position."""
        backup = self.backup
        dq, dv = backup.hold_deviation(_norm(self.v), _norm(a), self.dt)
        state = -math.inf
        for rows, near, far in split:
            x1 = [_dot(rows[j][0], q1) + rows[j][1] + _scaled(_norm(rows[j][0]), dq) for j in near]
            if x1 and max(x1) >= 0.0:
                continue
            value = far
            if near:
                reach = _state_reach(backup, [rows[j] for j in near], v1, dv)
                value = min(value, min(-(xj + r) for xj, r in zip(x1, reach)))
            state = max(state, value)
        return state


def _crude_rows(bounds: list):
    """rows → [Σ_b |K_j,b| C_b per row] for the block bounds C_b of `_block_bounds`."""
    def crude(rows):
        out = []
        for _, _, parts in rows:
            total = parts[0][1] * bounds[0]
            for b in range(1, len(bounds)):
                total += parts[b][1] * bounds[b]
            out.append(total)
        return out
    return crude


def _block_bounds(backup: BackupModel, v: list, a: list, dt: float) -> list[float]:
    """Per block, C_b = (|v_b| + |a_b| T)(T + dt) + s_b(|v_b| + |a_b| T) with T = max(T_w, dt): no
    row advances more than Σ_b |K_j,b| C_b, neither while a is held T_w then braked, nor over one
    period plus the stop of the state it leads to (docs/control.md §10). Floats in, floats out.

    With a hold deviation, (x, y) = hold_deviation(‖v‖, ‖a‖, T) and (x_g, y_g) that of the fallback
    from speed S = ‖v‖ + ‖a‖T + y: C_b = t_b(T + dt) + x + x_g + s_b(t_b + y_g), t_b = |v_b| + |a_b|T + y
    (‖K_j‖ ≤ Σ_b |K_j,b| since the blocks cover every coordinate, `_rows_of`)."""
    if backup.hold_deviation is not None:
        return _deviating_block_bounds(backup, v, a, dt)
    T = max(backup.hold, dt)
    bounds = []
    for block in backup.blocks:
        top = _norm([v[i] for i in block.axes]) + _norm([a[i] for i in block.axes]) * T
        bounds.append(top * (T + dt) + block.distance(top))
    return bounds


def _deviating_block_bounds(backup: BackupModel, v: list, a: list, dt: float) -> list[float]:
    """`_block_bounds` for a model with a hold deviation."""
    T = max(backup.hold, dt)
    dq, dv = backup.hold_deviation(_norm(v), _norm(a), T)
    speed = _norm(v) + _norm(a) * T + dv
    dq_g, dv_g = backup.hold_deviation(speed, _fallback_size(backup, speed), backup.hold)
    bounds = []
    for block in backup.blocks:
        top = _norm([v[i] for i in block.axes]) + _norm([a[i] for i in block.axes]) * T + dv
        bounds.append(top * (T + dt) + dq + dq_g + _braked_path(block, top + dv_g))
    return bounds


def _norm(x: list) -> float:
    """sqrt(x₀² + x₁² + …), summed left to right (as the batched _speed sums)."""
    total = x[0] * x[0]
    for xi in x[1:]:
        total = total + xi * xi
    return math.sqrt(total)


def _row_norms(backup: BackupModel, feasible) -> list[list[float]]:
    """Per polytope, per block, max_j |K_j,b| (cached on the feasible set)."""
    cache = feasible.__dict__.setdefault("_backup_row_norms", {})
    key = tuple(block.axes for block in backup.blocks)
    if key not in cache:
        cache[key] = [[float(np.max(np.linalg.norm(r.K[:, list(axes)], axis=1))) for axes in key]
                      for r in feasible.regions]
    return cache[key]


def _clearly_safe(backup: BackupModel, feasible, q: list, bounds: list) -> float:
    """A lower bound of the command's and the next state's backup margin (−inf if q is in no
    polytope): the best containing polytope's slack less Σ_b max_j|K_j,b| C_b. Where it is ≥ δ,
    `_Probe.merit` is ≥ 0 too (every row of that polytope is one that cannot decide)."""
    best = -math.inf
    for rows, norms in zip(_region_rows(backup, feasible), _row_norms(backup, feasible)):
        slack = -max(_dot(k, q) + t for k, t, _ in rows)
        if slack > 0.0:
            loss = norms[0] * bounds[0]
            for n, c in zip(norms[1:], bounds[1:]):
                loss = loss + n * c
            best = max(best, slack - loss)
    return best


def speed_aware_rows(backup: BackupModel, feasible, rows: tuple[list, list], v, far: float,
                     a=None) -> tuple[list, list]:
    """Definition 2's rows seen through the stop: inside a polytope, each row value x_j is moved
    towards its face by the state's reach (kept just inside, so that containment is unchanged);
    rates and rows already outside are left as they are. Classifying these makes a state
    hazardous when its distance to a face, less the travel while the loss of actuation is
    detected and the braking distance at the current speed, falls below the bands. With `a`,
    the acceleration of the operator's command, the reach is that of holding it (command_reach):
    the state is hazardous when the operator's own command would not be backup-safe, so the
    machine holds authority wherever the governor would have to change u_h.

    A row that stays at or below −`far` even moved by its crude bound Σ_b |K_j,b| C_b
    (`_block_bounds`, dt = 0) is returned unmoved: `far` is the widest band, b2, and Definition 2,
    the standoff test and the hand-back test classify a row there alike whether or not it is
    moved, so only the rows near a face pay for the exact reach."""
    values, rates = rows
    v_list = v.tolist() if isinstance(v, np.ndarray) else [float(e) for e in v]
    a_list = [0.0] * len(v_list) if a is None else _as_floats(a)
    stacked = _stacked_rows(backup, feasible)
    crude = _crude_rows(_block_bounds(backup, v_list, a_list, 0.0))(stacked)
    near = [j for j, (x, c) in enumerate(zip(values, crude)) if x < 0.0 and x + c > -far]
    if not near:
        return rows
    subset = [stacked[j] for j in near]
    reach = _state_reach(backup, subset, v_list) if a is None else _command_reach(backup, subset, v_list, a_list)
    shifted = list(values)
    for j, r in zip(near, reach):
        shifted[j] = min(values[j] + r, -_INSIDE)
    return shifted, rates


def _dot(k, v) -> float:
    """Σ k_i v_i left to right, as sum() adds (the same float result), without a generator."""
    n = len(k)
    if n == 3:
        return k[0] * v[0] + k[1] * v[1] + k[2] * v[2]
    if n == 2:
        return k[0] * v[0] + k[1] * v[1]
    total = 0.0
    for ki, vi in zip(k, v):
        total += ki * vi
    return total


def _as_floats(x) -> list[float]:
    return x.tolist() if isinstance(x, np.ndarray) else [float(e) for e in x]


def _rows_of(backup: BackupModel, K) -> list:
    """[(K_j, 0, [(K_j,b, |K_j,b|) per block]) …] for the rows of K, as floats. With a hold deviation
    the blocks must cover every coordinate (the deviation moves all of them)."""
    K = np.asarray(K, float)
    covered = sorted(i for b in backup.blocks for i in b.axes)
    if backup.hold_deviation is not None and covered != list(range(K.shape[1])):
        raise ValueError("backup: with a hold deviation the brake blocks must cover every coordinate once")
    parts = [[(tuple(K[j, list(b.axes)].tolist()), float(np.linalg.norm(K[j, list(b.axes)])))
              for b in backup.blocks] for j in range(K.shape[0])]
    return [(tuple(K[j].tolist()), 0.0, parts[j]) for j in range(K.shape[0])]


def _stacked_rows(backup: BackupModel, feasible) -> list:
    """`_rows_of` the feasible set's stacked rows (`row_matrix`, the order of `row_values`), cached on the set."""
    cache = feasible.__dict__.setdefault("_backup_stacked_rows", {})
    key = tuple(b.axes for b in backup.blocks)
    if key not in cache:
        cache[key] = _rows_of(backup, feasible.row_matrix)
    return cache[key]


def _region_rows(backup: BackupModel, feasible) -> list:
    """Per polytope, its rows as `_rows_of` gives them with T_j in place of 0 (cached on the set)."""
    cache = feasible.__dict__.setdefault("_backup_rows", {})
    key = tuple(b.axes for b in backup.blocks)
    if key not in cache:
        cache[key] = [[(k, float(t), parts) for (k, _, parts), t in zip(_rows_of(backup, r.K), r.T.tolist())]
                      for r in feasible.regions]
    return cache[key]


_LAMBDA_RESOLUTION = 2.0 ** -12   # govern's finest step in λ
_INSIDE = 1e-9      # m: a shifted row stays this far inside, so the row's polytope still contains q


#: Three wheels 120° apart, equal Coulomb brakes: within each 60° sector between two directions
#: in which one wheel does not turn, the brake force is constant and points against the sector's
#: bisector, so the velocity turns towards the sector's edge and at most 30° before it slides
#: along it (docs/control.md §10; tests/test_backup.py measures it on the robot's plant).
TRANSLATION_DEFLECTION = math.pi / 6


#: A real brake holds at rest; the simulated one is c_b tanh(ω/ω_b) (ω_b = 0.2 rad/s), which fades
#: below a wheel speed of a few ω_b, i.e. below about 1 cm/s: the last stretch of a stop is
#: slower than a_c allows. 0.5 mm covers it (measured excess over the closed form: ≤ 0.02 mm).
CREEP = 5e-4


def omni_backup(parameters, brake_torque: float, friction_coulomb: float, friction_viscous: float,
                hold: float, margin: float = 0.01) -> BackupModel:
    """The omnidirectional robot's stop (docs/safety.md §2): per wheel a Coulomb torque c + c_b and a
    viscous b. Translation: the least deceleration over directions, (c + c_b)√3/(r m1), and
    k = 3b/(2r²m1); yaw (every wheel at L_r): 3(c + c_b)L_r/(r m3) and 3bL_r²/(r²m3)."""
    r, L = parameters.wheel_radius, parameters.wheel_distance
    m1, m3, _ = (float(x) for x in parameters.theta())
    c = friction_coulomb + brake_torque
    translation = BrakeBlock((0, 1), c * math.sqrt(3.0) / (r * m1), 3.0 * friction_viscous / (2.0 * r * r * m1),
                             TRANSLATION_DEFLECTION, CREEP)
    yaw = BrakeBlock((2,), 3.0 * c * L / (r * m3), 3.0 * friction_viscous * L * L / (r * r * m3), 0.0, CREEP / L)
    return BackupModel(hold, (translation, yaw), margin)


def arm_backup(parameters, brake_torque, hold: float, margin: float = 0.01) -> BackupModel:
    """The two-link arm's stop (docs/control.md §10, "The arm's stop"): one block over both joints
    with a_c from the joint brakes' Coulomb torques `brake_torque` = (c1, c2) (N·m, each above its
    joint's largest gravity torque), k = 0 and deflection π; the hold's deviation from constant
    acceleration bounded per probe from ‖v‖, ‖a‖ and T (models/planar_arm_stop.py)."""
    bounds = ArmBounds.of(parameters.theta())
    block = BrakeBlock((0, 1), bounds.braking_deceleration(brake_torque), 0.0)
    return BackupModel(hold, (block,), margin, hold_deviation=ArmHoldDeviation.of(bounds))
