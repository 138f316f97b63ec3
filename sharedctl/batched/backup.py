"""backup.py for a whole batch: the fail-safe stop's reaches and margins, the fallback u_g, the
backup-safe governor and Definition 2's rows seen through the stop (docs/control.md §10).

Every function is the scalar one of sharedctl/backup.py written over the robots (last axis)
and over the feasible set's distinct rows (GroupTable's P rows: a row's reach depends on K_j
alone and its value on K_j, t_j, so a row shared by two polytopes is computed once and each
polytope's minimum and maximum read it through `region_rows`). The arithmetic is the scalar
code's, operation for operation: dot products are summed in its order (k₀x₀ + k₁x₁ + k₂x₂,
then + t_j), each branch of BrakeBlock.advance / distance and each Python min/max is an
np.where with the same comparison, so every value equals the scalar one to rounding and every
decision is the same. (Where the scalar code calls numpy — Y θ in inverse_dynamics — BLAS may
round differently from the plain sums here, in the last bit.)

`BackupTable.govern` searches all robots at once: the robots that need it run backup._root's
regula falsi together, each keeping its own bracket.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..backup import _INSIDE, _LAMBDA_RESOLUTION, BackupModel, BrakeBlock   # the scalar module's constants
from ..constraints import FeasibleSet
from .geometry import GroupTable
from .plant import acceleration, regressor_times


@dataclass(frozen=True)
class BrakeRows:
    """One BrakeBlock over the distinct rows it moves (|K_j,b| > 0; the others advance by 0): their
    indices, K_j,b (p, m) and |K_j,b| (p, 1), as backup._rows_of has them."""

    block: BrakeBlock
    axes: list
    rows: np.ndarray
    parts: np.ndarray
    norms: np.ndarray


@dataclass(frozen=True)
class BackupTable:
    """A BackupModel and the feasible set's distinct rows, per brake block."""

    model: BackupModel
    brakes: tuple
    row_K: np.ndarray          # (P, n)
    row_T: np.ndarray          # (P, 1)
    region_rows: tuple         # per polytope: its rows among the distinct rows
    region_norms: np.ndarray   # (R, B) max_j |K_j,b| per polytope and block (backup._row_norms)
    row_norms: tuple           # per block, |K_j,b| of every distinct row (P, 1)

    @staticmethod
    def of(model: BackupModel, feasible: FeasibleSet, table: GroupTable) -> "BackupTable":
        brakes = []
        for block in model.blocks:
            axes = list(block.axes)
            norms = np.array([float(np.linalg.norm(table.row_K[j, axes])) for j in range(table.row_K.shape[0])])
            rows = np.flatnonzero(norms > 0.0)
            brakes.append(BrakeRows(block, axes, rows, np.ascontiguousarray(table.row_K[np.ix_(rows, axes)]),
                                    norms[rows, None]))
        region_norms = np.array([[float(np.max(np.linalg.norm(r.K[:, list(b.axes)], axis=1))) for b in model.blocks]
                                 for r in feasible.regions])
        row_norms = tuple(np.array([[float(np.linalg.norm(k[list(b.axes)]))] for k in table.row_K])
                          for b in model.blocks)
        return BackupTable(model, tuple(brakes), table.row_K, table.row_T, table.region_rows, region_norms, row_norms)

    # ----- reach: how far each row may still move towards its face (P, N) --------------------
    def state_reach(self, v: np.ndarray) -> np.ndarray:
        """BackupModel.state_reach on the distinct rows: (K_j v)⁺ T_w, then the brakes from v."""
        w = _dot(self.row_K, v)
        reach = np.where(0.0 > w, 0.0, w) * self.model.hold            # max(w, 0.0) T
        return self._add_braking(v, reach)

    def command_reach(self, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """BackupModel.command_reach on the distinct rows: a held T_w (exact), then the brakes from v + a T_w."""
        T = self.model.hold
        w = _dot(self.row_K, v)
        alpha = _dot(self.row_K, a)
        advance = w * T + 0.5 * alpha * T * T
        advance = np.where(0.0 > advance, 0.0, advance)                 # max(·, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):       # α = 0: not turning (α < 0 is False)
            ratio = -w / alpha
            peak = -w * w / (2.0 * alpha)
        turning = (alpha < 0.0) & (0.0 < ratio) & (ratio < T)
        advance = np.where(turning & (peak > advance), peak, advance)   # max(advance, peak)
        return self._add_braking(v + a * T, advance)

    def _add_braking(self, v_end: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """reach (a fresh array) + each block's advance, block by block; rows a block does not move get + 0."""
        for brake in self.brakes:
            reach[brake.rows] += _advance(brake, v_end[brake.axes])
        return reach

    # ----- margins (N,) ---------------------------------------------------------------------------
    def values(self, q: np.ndarray) -> np.ndarray:
        """x_j = k_j q + t_j of the distinct rows, summed as backup._margin sums them."""
        x = _dot(self.row_K, q)
        x += self.row_T
        return x

    def margin(self, x: np.ndarray, reach: np.ndarray, skip=None, far=None) -> np.ndarray:
        """max over the polytopes containing q of min_j −(x_j + reach_j); −inf in none (backup._margin).
        With `skip`, those rows' values are `far` (backup._Probe.merit's rows that cannot decide)."""
        value = -(x + reach) if skip is None else np.where(skip, far, -(x + reach))
        best = np.full(x.shape[1], -np.inf)
        for rows in self.region_rows:
            inside = x[rows].max(axis=0) < 0.0
            least = value[rows].min(axis=0)
            best = np.where(inside & (least > best), least, best)
        return best

    def state_margin(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return self.margin(self.values(q), self.state_reach(v))

    def command_margin(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        return self.margin(self.values(q), self.command_reach(v, a))

    # ----- the fallback and the governor -----------------------------------------------------------
    def fallback_acceleration(self, v: np.ndarray) -> np.ndarray:
        """a_g (BackupModel.fallback_acceleration): each block along −v_b at a_c + k|v_b| + a_extra, or
        stopped within T_w when that is gentler."""
        model = self.model
        a = np.zeros_like(v)
        for brake in self.brakes:
            block, part = brake.block, v[brake.axes]
            speed = _speed(part)
            decel = block.coulomb + block.viscous * speed + model.extra_deceleration
            if model.hold > 0.0:
                stop = speed / model.hold
                decel = np.where(stop < decel, stop, decel)           # min(decel, speed / T)
            with np.errstate(divide="ignore", invalid="ignore"):   # a block at rest keeps a_g = 0
                a[brake.axes] = np.where(speed <= 0.0, 0.0, -decel * part / speed)
        return a

    def govern(self, theta: np.ndarray, q: np.ndarray, v: np.ndarray, u: np.ndarray, dt: float):
        """backup.govern for every robot (true parameters θ (n_θ, N), q, v, u (n, N)): returns
        (the command to send (n, N), λ (N,)). u where it is backup-safe; where not even u_g is, the one of
        u and u_g whose stop ends farther inside (λ = 0 or 1); elsewhere u + λ(u_g − u) with λ from
        backup._root's regula falsi, every robot its own bracket."""
        model = self.model
        delta = model.margin
        a = acceleration(theta, v, u, np.empty_like(u))
        sent, share = u.copy(), np.zeros(u.shape[1])
        slack = self._clearly_safe(self.values(q), v, a, dt)
        cols = np.flatnonzero(~(slack >= delta))
        if cols.size == 0:
            return sent, share
        theta, q, v, u, a = (arr.take(cols, axis=1) for arr in (theta, q, v, u, a))
        x = self.values(q)
        m_u = self._merit(q, v, x, a, dt)
        keep = ~(m_u >= 0.0)
        cols = cols[keep]
        if cols.size == 0:
            return sent, share
        theta, q, v, u, x, a = (arr[:, keep] for arr in (theta, q, v, u, x, a))
        m_u = m_u[keep]
        a_g = self.fallback_acceleration(v)
        m_g = self._merit(q, v, x, a_g, dt)
        keep = m_g >= 0.0
        hopeless = np.flatnonzero(~keep)                      # outside the envelope: u_g where the next state's
        if hopeless.size:                                     # backup margin is larger after it (backup.govern)
            qh, vh = q[:, hopeless], v[:, hopeless]
            after_u = self._next_margin(qh, vh, a[:, hopeless], dt)
            hopeless = hopeless[~(after_u >= self._next_margin(qh, vh, a_g[:, hopeless], dt))]
        if hopeless.size:
            sent[:, cols[hopeless]] = regressor_times(v[:, hopeless], v[:, hopeless], a_g[:, hopeless],
                                                      theta[:, hopeless])
            share[cols[hopeless]] = 1.0
        cols = cols[keep]
        if cols.size == 0:
            return sent, share
        theta, q, v, u, x, a, a_g = (arr[:, keep] for arr in (theta, q, v, u, x, a, a_g))
        hi = self._root(q, v, x, a, a_g - a, m_u[keep], m_g[keep], dt)
        u_g = regressor_times(v, v, a_g, theta)                        # model.inverse_dynamics
        sent[:, cols] = u + hi * (u_g - u)
        share[cols] = hi
        return sent, share

    def _next_margin(self, q, v, a, dt: float) -> np.ndarray:
        """backup._next_margin: the backup margin of the state one period on under a."""
        return self.state_margin(q + v * dt + 0.5 * a * dt * dt, v + a * dt)

    def _root(self, q, v, x, a, step, f_lo, f_hi, dt: float) -> np.ndarray:
        """backup._root for every robot: regula falsi with the Illinois rule on [lo, hi], the same
        arithmetic; a robot whose bracket is done stops changing."""
        model = self.model
        lo, hi = np.zeros(f_lo.size), np.ones(f_lo.size)
        kept = np.zeros(f_lo.size)
        for _ in range(model.iterations):
            active = ~(hi - lo <= _LAMBDA_RESOLUTION)
            cols = np.flatnonzero(active)
            if cols.size == 0:
                break
            low, h, fl, fh = lo[cols], hi[cols], f_lo[cols], f_hi[cols]
            with np.errstate(divide="ignore", invalid="ignore"):     # f_lo = −inf: the midpoint
                lam = (low * fh - h * fl) / (fh - fl)
            lam = np.where((low < lam) & (lam < h), lam, 0.5 * (low + h))
            m = self._merit(q[:, cols], v[:, cols], x[:, cols], a[:, cols] + lam * step[:, cols], dt)
            passed = m >= 0.0
            k = kept[cols]
            hi[cols] = np.where(passed, lam, h)
            f_hi[cols] = np.where(passed, m, np.where(k > 0, 0.5 * fh, fh))
            lo[cols] = np.where(passed, low, lam)
            f_lo[cols] = np.where(passed, np.where(k < 0, 0.5 * fl, fl), m)
            kept[cols] = np.where(passed, -1.0, 1.0)
        return hi

    def _merit(self, q, v, x, a, dt: float) -> np.ndarray:
        """backup._Probe.merit: min(command margin, the next state's backup margin) − δ, or the
        command margin − δ where that fails; a row whose crude bound stays ≤ −δ counts with that
        bound. `x`: the row values at q."""
        delta = self.model.margin
        crude = self._crude(self._block_bounds(v, a, dt))
        far = -(x + crude)
        skip = ~(x + crude > -delta)
        command = self.margin(x, self.command_reach(v, a), skip, far)
        merit = command - delta
        cols = np.flatnonzero(~(command < delta))
        if cols.size:
            qc, vc, ac = q[:, cols], v[:, cols], a[:, cols]
            x1 = self.values(qc + vc * dt + 0.5 * ac * dt * dt)
            sk = skip[:, cols]
            x1 = np.where(sk, -1.0, x1)                    # a row that cannot decide is inside
            state = self.margin(x1, self.state_reach(vc + ac * dt), sk, far[:, cols])
            held = command[cols]
            merit[cols] = np.where(state < held, state, held) - delta      # min(command, state)
        return merit

    def _crude(self, bounds: list) -> np.ndarray:
        """Σ_b |K_j,b| C_b per distinct row and robot (P, N), summed in block order (backup._crude_rows)."""
        total = self.row_norms[0] * bounds[0]
        for n, c in zip(self.row_norms[1:], bounds[1:]):
            total = total + n * c
        return total

    def _block_bounds(self, v, a, dt: float) -> list:
        """backup._block_bounds per robot: (|v_b| + |a_b| T)(T + dt) + s_b(|v_b| + |a_b| T), T = max(T_w, dt)."""
        T = max(self.model.hold, dt)
        bounds = []
        for brake in self.brakes:
            top = _speed(v[brake.axes]) + _speed(a[brake.axes]) * T
            bounds.append(top * (T + dt) + _distance(brake.block, top))
        return bounds

    def _clearly_safe(self, x, v, a, dt: float) -> np.ndarray:
        """backup._clearly_safe per robot: the best containing polytope's slack less Σ_b max_j|K_j,b| C_b."""
        bounds = self._block_bounds(v, a, dt)
        best = np.full(x.shape[1], -np.inf)
        for rows, norms in zip(self.region_rows, self.region_norms.tolist()):
            slack = -x[rows].max(axis=0)
            loss = norms[0] * bounds[0]
            for n, c in zip(norms[1:], bounds[1:]):
                loss = loss + n * c
            value = slack - loss
            best = np.where((slack > 0.0) & (value > best), value, best)
        return best

    # ----- Definition 2 through the stop -------------------------------------------------------------
    def speed_aware_rows(self, x: np.ndarray, v: np.ndarray, far: float, a: np.ndarray | None = None) -> np.ndarray:
        """backup.speed_aware_rows on the row values x (P, N): each x_j < 0 moved towards its face by
        the state's reach (with `a`, that of holding the acceleration a), kept _INSIDE inside; a
        row that stays at or below −`far` under its crude bound is left unmoved."""
        held = np.zeros_like(v) if a is None else a
        crude = self._crude(self._block_bounds(v, held, 0.0))
        near = (x < 0.0) & (x + crude > -far)
        cols = np.flatnonzero(near.any(axis=0))
        if cols.size == 0:
            return x
        xs, vs = x[:, cols], v[:, cols]
        reach = self.state_reach(vs) if a is None else self.command_reach(vs, a[:, cols])
        moved = xs + reach
        moved = np.where(-_INSIDE < moved, -_INSIDE, moved)          # min(x + r, −_INSIDE)
        out = x.copy()
        out[:, cols] = np.where(near[:, cols], moved, xs)
        return out


def _dot(K: np.ndarray, x: np.ndarray) -> np.ndarray:
    """K x (P, N) for K (P, m), x (m, N), summed left to right (Python's sum over zip(k, x))."""
    out = K[:, :1] * x[0]
    for j in range(1, K.shape[1]):
        out += K[:, j:j + 1] * x[j]
    return out


def _speed(part: np.ndarray) -> np.ndarray:
    """|v_b| (N,) for the block's components (m, N)."""
    total = part[0] * part[0]
    for row in part[1:]:
        total = total + row * row
    return np.sqrt(total)


def _distance(block: BrakeBlock, speed: np.ndarray) -> np.ndarray:
    """BrakeBlock.distance per robot."""
    a, k = block.coulomb, block.viscous
    out = speed * speed / (2.0 * a)
    if k > 0.0:
        closed = speed / k - (a / (k * k)) * np.log1p(k * speed / a)
        out = np.where(k * speed < 1e-6 * a, out, closed)
    out = out + block.creep
    return np.where(speed <= 0.0, 0.0, out)


def _advance(brake: BrakeRows, v_block: np.ndarray) -> np.ndarray:
    """BrakeBlock.advance for the rows the block moves and every robot (p, N). At rest (speed 0)
    s_b = 0, and every branch below gives 0 as the scalar code does."""
    block, norms = brake.block, brake.norms
    speed = _speed(v_block)
    reach = _distance(block, speed)
    if block.deflection >= math.pi:
        return norms * reach
    with np.errstate(divide="ignore", invalid="ignore"):           # at rest: s_b = 0 below
        cosine = _dot(brake.parts, v_block) / (norms * speed)
    cosine = np.where(cosine < 1.0, cosine, 1.0)                       # min(1.0, ·)
    cosine = np.where(cosine > -1.0, cosine, -1.0)                     # max(−1.0, ·)
    cos_d, sin_d = block.cone
    with np.errstate(invalid="ignore"):                                 # at rest: s_b = 0 below
        turned = cosine * cos_d + np.sqrt(1.0 - cosine * cosine) * sin_d
    full = norms * reach
    return np.where(cosine >= cos_d, full, np.where(turned > 0.0, full * turned, 0.0))
