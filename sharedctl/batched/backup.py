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

The hold deviation, the energy speeds of shared brakes and an uncertain velocity (`slack`, output
feedback) follow backup.py's `_uncertain_*` functions the same way; a hold deviation must bound each
block (`by_block`, as the omnidirectional robot's does) with arithmetic that runs on arrays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..backup import _INSIDE, _LAMBDA_RESOLUTION, BackupModel, BrakeBlock   # the scalar module's constants
from ..constraints import FeasibleSet
from .compiled_backup import CompiledBackup
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
    compiled: object = None    # compiled_backup.CompiledBackup: govern and speed_aware_rows robot by robot

    @staticmethod
    def of(model: BackupModel, feasible: FeasibleSet, table: GroupTable, compiled: bool | None = None) -> "BackupTable":
        """The table of `model` on `feasible`'s rows; `compiled`: run govern and speed_aware_rows compiled
        (compiled_backup.py) — None: wherever that has a form for the model and numba is installed;
        True: required (ValueError where it has none); False: the numpy code below."""
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
        out = BackupTable(model, tuple(brakes), table.row_K, table.row_T, table.region_rows, region_norms, row_norms)
        if compiled is False:
            return out
        fast = CompiledBackup.of(out)
        if fast is None and compiled:
            raise ValueError("no compiled governor for this model here (numba missing, or not the omni robot's stop)")
        return replace(out, compiled=fast)

    # ----- reach: how far each row may still move towards its face (P, N) --------------------
    def state_reach(self, v: np.ndarray, slack=None, estimated: bool = True) -> np.ndarray:
        """BackupModel.state_reach on the distinct rows: Σ_b (K_j,b v_b)⁺ T_w, then the brakes from v
        (backup._state_reach; with a hold deviation or a slack, backup._uncertain_state_reach)."""
        if self.model.hold_deviation is not None or slack is not None:
            return self._uncertain_state_reach(v, slack, estimated)
        T = self.model.hold
        reach = np.zeros((self.row_K.shape[0], v.shape[1]))
        for brake in self.brakes:
            w = _dot(brake.parts, v[brake.axes])
            reach[brake.rows] += np.where(0.0 > w, 0.0, w) * T           # max(w, 0.0) T
        return self._add_braking(v, reach)

    def command_reach(self, v: np.ndarray, a: np.ndarray, slack=None) -> np.ndarray:
        """BackupModel.command_reach on the distinct rows: a held T_w (exact), then the brakes from v + a T_w."""
        if self.model.hold_deviation is not None or slack is not None:
            return self._uncertain_command_reach(v, a, slack)
        T = self.model.hold
        w = _dot(self.row_K, v)
        alpha = _dot(self.row_K, a)
        return self._add_braking(v + a * T, _held_advance(w, alpha, T))

    def _add_braking(self, v_end: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """reach (a fresh array) + each block's advance, block by block; rows a block does not move get + 0."""
        speeds = [_speed(v_end[brake.axes]) for brake in self.brakes]
        for b, brake in enumerate(self.brakes):
            reach[brake.rows] += _advance(brake, v_end[brake.axes], _braking_speed(brake.block, b, speeds))
        return reach

    # ----- a hold that departs from constant acceleration, an uncertain velocity ----------------
    def _uncertain_state_reach(self, v: np.ndarray, slack, estimated: bool = True) -> np.ndarray:
        """backup._uncertain_state_reach per robot; `slack` (B, N) or None."""
        T = self.model.hold
        speeds = [_speed(v[brake.axes]) for brake in self.brakes]
        eps, eta, dq, spread = self._state_head(speeds, slack, estimated)
        reach = np.zeros((self.row_K.shape[0], v.shape[1]))
        for b, brake in enumerate(self.brakes):
            w = _dot(brake.parts, v[brake.axes])
            norm = brake.norms
            reach[brake.rows] += (np.where(0.0 > w, 0.0, w) + norm * eps[b]) * T + 0.5 * norm * eta[b] * T * T \
                + norm * dq[b]
        return self._add_uncertain_braking(v, speeds, spread, reach)

    def _state_head(self, speeds: list, slack, estimated: bool) -> tuple:
        """backup._state_head per robot (without T_w): (ε, η, x, the braking speeds' spread)."""
        T = self.model.hold
        eps = _eps(slack, speeds)
        eta = self._spread(speeds, slack if estimated else None)
        top = [s + e for s, e in zip(speeds, eps)]
        dq, dv = self._deviation(top, [d + h for d, h in zip(self._fallback_decelerations(top), eta)], T)
        return eps, eta, dq, [e + h * T + y for e, h, y in zip(eps, eta, dv)]

    def _command_head(self, speeds: list, held: list, slack) -> tuple:
        """backup._command_head per robot (without T_w), for block accelerations (bounds) `held`."""
        T = self.model.hold
        eps = _eps(slack, speeds)
        eta = self._spread(speeds, slack)
        dq, dv = self._deviation([s + e for s, e in zip(speeds, eps)], [h + al for h, al in zip(eta, held)], T)
        return eps, eta, dq, [e + h * T + y for e, h, y in zip(eps, eta, dv)]

    def _uncertain_command_reach(self, v: np.ndarray, a: np.ndarray, slack) -> np.ndarray:
        """backup._uncertain_command_reach per robot."""
        T = self.model.hold
        eps, eta, dq, spread = self._command_head([_speed(v[brake.axes]) for brake in self.brakes],
                                                  [_speed(a[brake.axes]) for brake in self.brakes], slack)
        w = _dot(self.row_K, v)
        alpha = _dot(self.row_K, a)
        held = np.zeros_like(w)
        for b, norms in enumerate(self.row_norms):
            w += norms * eps[b]
            alpha += norms * eta[b]
            held += np.where(norms > 0.0, norms * dq[b], 0.0)
        reach = _held_advance(w, alpha, T) + held
        v_end = v + a * T
        return self._add_uncertain_braking(v_end, [_speed(v_end[brake.axes]) for brake in self.brakes], spread, reach)

    def _add_uncertain_braking(self, v_end, speeds, spread, reach) -> np.ndarray:
        """backup._add_uncertain_braking: from speeds |v_b| + spread_b, in any direction where spread_b > 0."""
        top = [s + e for s, e in zip(speeds, spread)]
        for b, brake in enumerate(self.brakes):
            block = brake.block
            speed = _braking_speed(block, b, top)
            full = brake.norms * _distance(block, speed)
            if block.deflection < math.pi:
                full = np.where(spread[b] > 0.0, full, _advance(brake, v_end[brake.axes], speed))
            reach[brake.rows] += full
        return reach

    def _fallback_decelerations(self, speeds: list) -> list:
        """backup._fallback_decelerations per robot."""
        model, out = self.model, []
        for b, brake in enumerate(self.brakes):
            block = brake.block
            decel = block.coulomb + block.viscous * _braking_speed(block, b, speeds) + model.extra_deceleration
            if model.hold > 0.0:
                stop = speeds[b] / model.hold
                decel = np.where(stop < decel, stop, decel)               # min(decel, speed / T)
            out.append(decel)
        return out

    def _deviation(self, speeds: list, accelerations: list, duration: float) -> tuple[list, list]:
        """backup._deviation per robot (zeros without a hold deviation)."""
        deviation = self.model.hold_deviation
        if deviation is None:
            zeros = [np.zeros_like(speeds[0])] * len(speeds)
            return zeros, zeros
        xs, ys = deviation.by_block(speeds, accelerations, duration)
        return list(xs), list(ys)

    def _spread(self, speeds: list, slack) -> list:
        """backup._spread per robot."""
        spread = getattr(self.model.hold_deviation, "acceleration_spread", None)
        if slack is None or spread is None:
            return [np.zeros_like(speeds[0])] * len(speeds)
        return list(spread(speeds, list(slack)))

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

    def state_margin(self, q: np.ndarray, v: np.ndarray, slack=None) -> np.ndarray:
        return self.margin(self.values(q), self.state_reach(v, slack))

    def command_margin(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, slack=None) -> np.ndarray:
        return self.margin(self.values(q), self.command_reach(v, a, slack))

    # ----- the fallback and the governor -----------------------------------------------------------
    def fallback_acceleration(self, v: np.ndarray) -> np.ndarray:
        """a_g (BackupModel.fallback_acceleration): each block along −v_b at a_c + k S_b + a_extra, or
        stopped within T_w when that is gentler."""
        a = np.zeros_like(v)
        speeds = [_speed(v[brake.axes]) for brake in self.brakes]
        for brake, speed, decel in zip(self.brakes, speeds, self._fallback_decelerations(speeds)):
            part = v[brake.axes]
            with np.errstate(divide="ignore", invalid="ignore"):   # a block at rest keeps a_g = 0
                a[brake.axes] = np.where(speed <= 0.0, 0.0, -decel * part / speed)
        return a

    def govern(self, theta: np.ndarray, q: np.ndarray, v: np.ndarray, u: np.ndarray, dt: float, slack=None,
               hint=None):
        """backup.govern for every robot (true parameters θ (n_θ, N), q, v, u (n, N); `slack` per block, a
        float or (N,) each, or None; `hint` (N,) or None: each robot's last λ): returns (the command to
        send (n, N), λ (N,)). u where it is backup-safe; where not even u_g is, the one of u and u_g
        backup.govern sends there (λ = 0 or 1); elsewhere u + λ(u_g − u) with λ from backup._root's
        regula falsi, every robot its own bracket."""
        if self.compiled is not None:
            return self.compiled.govern(theta, q, v, u, dt, slack, hint)
        model = self.model
        delta = model.margin
        a = acceleration(theta, v, u, np.empty_like(u))
        sent, share = u.copy(), np.zeros(u.shape[1])
        clear = self._clearly_safe(self.values(q), v, a, dt, slack)
        cols = np.flatnonzero(~(clear >= delta))
        if cols.size == 0:
            return sent, share
        theta, q, v, u, a = (arr.take(cols, axis=1) for arr in (theta, q, v, u, a))
        slack = _take(slack, cols)
        x = self.values(q)
        m_u = self._merit(q, v, x, a, dt, slack)
        keep = ~(m_u >= 0.0)
        cols = cols[keep]
        if cols.size == 0:
            return sent, share
        theta, q, v, u, x, a = (arr[:, keep] for arr in (theta, q, v, u, x, a))
        slack = _take(slack, keep)
        m_u = m_u[keep]
        a_g = self.fallback_acceleration(v)
        m_g = self._merit(q, v, x, a_g, dt, slack)
        keep = m_g >= 0.0
        hopeless = np.flatnonzero(~keep)                      # outside the envelope: u or u_g as
        if hopeless.size:                                     # backup.govern chooses
            qh, vh, sh = q[:, hopeless], v[:, hopeless], _take(slack, hopeless)
            after_u = self._next_margin(qh, vh, a[:, hopeless], dt, sh)
            keeps_u = ((after_u >= self._next_margin(qh, vh, a_g[:, hopeless], dt, sh))
                       & ((self.command_margin(qh, vh, a[:, hopeless], sh) >= delta)
                          | ~(self.command_margin(qh, vh, a_g[:, hopeless], sh) >= delta)))
            hopeless = hopeless[~keeps_u]
        if hopeless.size:
            sent[:, cols[hopeless]] = regressor_times(v[:, hopeless], v[:, hopeless], a_g[:, hopeless],
                                                      theta[:, hopeless])
            share[cols[hopeless]] = 1.0
        cols = cols[keep]
        if cols.size == 0:
            return sent, share
        theta, q, v, u, x, a, a_g = (arr[:, keep] for arr in (theta, q, v, u, x, a, a_g))
        slack = _take(slack, keep)
        hi = self._root(q, v, x, a, a_g, m_u[keep], m_g[keep], dt, slack,
                        None if hint is None else np.asarray(hint, float)[cols])
        u_g = regressor_times(v, v, a_g, theta)                        # model.inverse_dynamics
        sent[:, cols] = u + hi * (u_g - u)
        share[cols] = hi
        return sent, share

    def _next_margin(self, q, v, a, dt: float, slack=None) -> np.ndarray:
        """backup._next_margin: the backup margin of the state one period on under a."""
        return self.state_margin(q + v * dt + 0.5 * a * dt * dt, v + a * dt, slack)

    def _segment(self, v, a_u, a_g, dt: float, slack) -> list:
        """backup._Probe.along's crude bounds per robot, at the segment's largest block norms |a_b|."""
        held = [np.where(ny > nx, ny, nx)                             # max(|a_u,b|, |a_g,b|)
                for nx, ny in zip(self._speeds(a_u), self._speeds(a_g))]
        return self._block_bounds(v, a_u, dt, slack, held)

    def _speeds(self, v) -> list:
        """|v_b| per block (N,) each."""
        return [_speed(v[brake.axes]) for brake in self.brakes]

    def _root(self, q, v, x, a, a_g, f_lo, f_hi, dt: float, slack=None, hint=None) -> np.ndarray:
        """backup._root for every robot: regula falsi with the Illinois rule on [lo, hi], the same
        arithmetic, after the hint and its neighbour where 0 < hint < 1; a robot whose bracket is done
        stops changing. With a hold deviation or a slack, the probes share backup._Probe.along's crude
        bounds."""
        model = self.model
        step = a_g - a
        segment = (self._segment(v, a, a_g, dt, slack)
                   if model.hold_deviation is not None or slack is not None else None)
        lo, hi = np.zeros(f_lo.size), np.ones(f_lo.size)
        kept, probes = np.zeros(f_lo.size), np.zeros(f_lo.size, np.int64)   # each robot's at most model.iterations

        def settle(cols, lam):
            """Probe λ = lam at robots `cols` and move the end of each bracket its verdict replaces."""
            m = self._merit(q[:, cols], v[:, cols], x[:, cols], a[:, cols] + lam * step[:, cols], dt,
                            _take(slack, cols), None if segment is None else [c[cols] for c in segment])
            passed = m >= 0.0
            probes[cols] += 1
            hi[cols], f_hi[cols] = np.where(passed, lam, hi[cols]), np.where(passed, m, f_hi[cols])
            lo[cols], f_lo[cols] = np.where(passed, lo[cols], lam), np.where(passed, f_lo[cols], m)
            return passed

        warm = np.flatnonzero((0.0 < hint) & (hint < 1.0)) if hint is not None else np.zeros(0, np.intp)
        if warm.size:
            lam = _on_grid(hint[warm], 0.0, 1.0)
            passed = settle(warm, lam)
            wide = hi[warm] - lo[warm] > _LAMBDA_RESOLUTION
            if wide.any():
                settle(warm[wide], np.where(passed, lam - _LAMBDA_RESOLUTION, lam + _LAMBDA_RESOLUTION)[wide])
        for _ in range(model.iterations):
            active = ~(hi - lo <= _LAMBDA_RESOLUTION) & (probes < model.iterations)
            cols = np.flatnonzero(active)
            if cols.size == 0:
                break
            low, h, fl, fh = lo[cols], hi[cols], f_lo[cols], f_hi[cols]
            with np.errstate(divide="ignore", invalid="ignore"):     # f_lo = −inf: the midpoint
                lam = (low * fh - h * fl) / (fh - fl)
            lam = np.where((low < lam) & (lam < h), lam, 0.5 * (low + h))
            lam = _on_grid(lam, low, h)
            m = self._merit(q[:, cols], v[:, cols], x[:, cols], a[:, cols] + lam * step[:, cols], dt,
                            _take(slack, cols), None if segment is None else [c[cols] for c in segment])
            passed = m >= 0.0
            k = kept[cols]
            hi[cols] = np.where(passed, lam, h)
            f_hi[cols] = np.where(passed, m, np.where(k > 0, 0.5 * fh, fh))
            lo[cols] = np.where(passed, low, lam)
            f_lo[cols] = np.where(passed, np.where(k < 0, 0.5 * fl, fl), m)
            kept[cols] = np.where(passed, -1.0, 1.0)
            probes[cols] += 1
        while True:                                  # backup._root: bisect the brackets the chords left wide
            cols = np.flatnonzero(~(hi - lo <= _LAMBDA_RESOLUTION))
            if cols.size == 0:
                break
            low, h = lo[cols], hi[cols]
            lam = _on_grid(0.5 * (low + h), low, h)
            m = self._merit(q[:, cols], v[:, cols], x[:, cols], a[:, cols] + lam * step[:, cols], dt,
                            _take(slack, cols), None if segment is None else [c[cols] for c in segment])
            passed = m >= 0.0
            hi[cols] = np.where(passed, lam, h)
            lo[cols] = np.where(passed, low, lam)
        return hi

    def _merit(self, q, v, x, a, dt: float, slack=None, bounds=None) -> np.ndarray:
        """backup._Probe.merit: min(command margin, the next state's backup margin) − δ, or the
        command margin − δ where that fails; a row whose crude bound stays ≤ −δ counts with that
        bound. `x`: the row values at q. `bounds` (`_segment`, these robots'): the block bounds that
        sort the rows, backup._Probe.along's for the root search (default: a's own)."""
        delta = self.model.margin
        crude = self._crude(self._block_bounds(v, a, dt, slack) if bounds is None else bounds)
        command_reach = self.command_reach(v, a, slack)
        far = -(x + crude)
        skip = ~(x + crude > -delta)
        command = self.margin(x, command_reach, skip, far)
        merit = command - delta
        cols = np.flatnonzero(~(command < delta))
        if cols.size:
            qc, vc, ac = q[:, cols], v[:, cols], a[:, cols]
            x1 = self.values(qc + vc * dt + 0.5 * ac * dt * dt)
            v1, slack1 = vc + ac * dt, None
            if self.model.hold_deviation is not None or slack is not None:
                x1, slack1 = self._uncertain_next(x1, vc, ac, dt, _take(slack, cols))
            reach = self.state_reach(v1, slack1, slack is not None)
            sk = skip[:, cols]
            x1 = np.where(sk, -1.0, x1)                    # a row that cannot decide is inside
            state = self.margin(x1, reach, sk, far[:, cols])
            held = command[cols]
            merit[cols] = np.where(state < held, state, held) - delta      # min(command, state)
        return merit

    def _uncertain_next(self, x1, v, a, dt: float, slack):
        """backup._Probe._uncertain_state's row values of the next state (x1 moved by Σ_b |K_j,b| (ε_b dt +
        ½η_b dt² + x_b)) and its slack ε_b + η_b dt + y_b."""
        speeds = [_speed(v[brake.axes]) for brake in self.brakes]
        eps = _eps(slack, speeds)
        eta = self._spread(speeds, slack)
        held = [_speed(a[brake.axes]) for brake in self.brakes]
        dq, dv = self._deviation([s + e for s, e in zip(speeds, eps)], [h + al for h, al in zip(eta, held)], dt)
        moved = [e * dt + 0.5 * h * dt * dt + x for e, h, x in zip(eps, eta, dq)]
        for norms, m in zip(self.row_norms, moved):
            x1 = x1 + np.where(norms > 0.0, norms * m, 0.0)
        return x1, [e + h * dt + y for e, h, y in zip(eps, eta, dv)]

    def _crude(self, bounds: list) -> np.ndarray:
        """Σ_b |K_j,b| C_b per distinct row and robot (P, N), summed in block order (backup._crude_rows)."""
        total = self.row_norms[0] * bounds[0]
        for n, c in zip(self.row_norms[1:], bounds[1:]):
            total = total + n * c
        return total

    def _block_bounds(self, v, a, dt: float, slack=None, held=None) -> list:
        """backup._block_bounds per robot: t_b(T + dt) + s_b(S_b(t)), t_b = |v_b| + |a_b| T, T = max(T_w, dt);
        with a hold deviation or a slack, backup._uncertain_block_bounds (`held`: bounds of |a_b|,
        backup._uncertain_bounds_at)."""
        model = self.model
        T = max(model.hold, dt)
        if model.hold_deviation is None and slack is None:
            tops = [_speed(v[brake.axes]) + _speed(a[brake.axes]) * T for brake in self.brakes]
            return [top * (T + dt) + _distance(brake.block, _braking_speed(brake.block, b, tops))
                    for b, (brake, top) in enumerate(zip(self.brakes, tops))]
        speeds = [_speed(v[brake.axes]) for brake in self.brakes]
        eps = _eps(slack, speeds)
        eta = self._spread(speeds, slack)
        if held is None:
            held = [_speed(a[brake.axes]) for brake in self.brakes]
        accelerations = [h + al for h, al in zip(eta, held)]
        dq, dv = self._deviation([s + e for s, e in zip(speeds, eps)], accelerations, T)
        tops = [s + e + al * T + y for s, e, al, y in zip(speeds, eps, accelerations, dv)]
        eta_top = self._spread(tops, None if slack is None else tops)
        falls = [d + h for d, h in zip(self._fallback_decelerations(tops), eta_top)]
        dq_g, dv_g = self._deviation(tops, falls, model.hold)
        ends = [t + h * T + y for t, h, y in zip(tops, eta_top, dv_g)]
        return [top * (T + dt) + x + 0.5 * h * T * T + x_g
                + _distance(brake.block, _braking_speed(brake.block, b, ends))
                for b, (brake, top, x, h, x_g) in enumerate(zip(self.brakes, tops, dq, eta_top, dq_g))]

    def _clearly_safe(self, x, v, a, dt: float, slack=None) -> np.ndarray:
        """backup._clearly_safe per robot: the best containing polytope's slack less Σ_b max_j|K_j,b| C_b."""
        bounds = self._block_bounds(v, a, dt, slack)
        best = np.full(x.shape[1], -np.inf)
        for rows, norms in zip(self.region_rows, self.region_norms.tolist()):
            room = -x[rows].max(axis=0)
            loss = norms[0] * bounds[0]
            for n, c in zip(norms[1:], bounds[1:]):
                loss = loss + n * c
            value = room - loss
            best = np.where((room > 0.0) & (value > best), value, best)
        return best

    # ----- Definition 2 through the stop -------------------------------------------------------------
    def speed_aware_rows(self, x: np.ndarray, v: np.ndarray, far: float, a: np.ndarray | None = None,
                         slack=None) -> np.ndarray:
        """backup.speed_aware_rows on the row values x (P, N): each x_j < 0 moved towards its face by
        the state's reach (with `a`, that of holding the acceleration a; with `slack`, of every velocity
        that close to v), kept _INSIDE inside; a row that stays at or below −`far` under its crude bound
        is left unmoved."""
        if self.compiled is not None:
            return self.compiled.speed_aware_rows(x, v, far, a, slack)
        held = np.zeros_like(v) if a is None else a
        crude = self._crude(self._block_bounds(v, held, 0.0, slack))
        near = (x < 0.0) & (x + crude > -far)
        cols = np.flatnonzero(near.any(axis=0))
        if cols.size == 0:
            return x
        xs, vs, sl = x[:, cols], v[:, cols], _take(slack, cols)
        reach = self.state_reach(vs, sl) if a is None else self.command_reach(vs, a[:, cols], sl)
        moved = xs + reach
        moved = np.where(-_INSIDE < moved, -_INSIDE, moved)          # min(x + r, −_INSIDE)
        out = x.copy()
        out[:, cols] = np.where(near[:, cols], moved, xs)
        return out


def _on_grid(lam, lo, hi):
    """backup._on_grid for arrays: λ rounded to the nearest multiple of the resolution strictly inside [lo, hi]."""
    r = _LAMBDA_RESOLUTION
    return np.minimum(np.maximum(np.round(lam / r) * r, lo + r), hi - r)


def _take(slack, cols):
    """The slack of the robots `cols` (indices or a mask): per block a float (every robot's) or (N,)."""
    if slack is None:
        return None
    return [e if np.ndim(e) == 0 else e[cols] for e in slack]


def _eps(slack, speeds: list) -> list:
    """The slack per block, zeros without one (backup's [0.0] * n)."""
    return [np.zeros_like(s) for s in speeds] if slack is None else [e + 0.0 * s for e, s in zip(slack, speeds)]


def _held_advance(w: np.ndarray, alpha: np.ndarray, T: float) -> np.ndarray:
    """The largest w t + ½αt² over t ∈ [0, T] and 0 (backup._command_reach's advance per row)."""
    advance = w * T + 0.5 * alpha * T * T
    advance = np.where(0.0 > advance, 0.0, advance)                 # max(·, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):       # α = 0: not turning (α < 0 is False)
        ratio = -w / alpha
        peak = -w * w / (2.0 * alpha)
    turning = (alpha < 0.0) & (0.0 < ratio) & (ratio < T)
    return np.where(turning & (peak > advance), peak, advance)   # max(advance, peak)


def _braking_speed(block: BrakeBlock, b: int, speeds: list) -> np.ndarray:
    """BrakeBlock.braking_speed per robot."""
    w = block.energy_weights
    if not w:
        return speeds[b]
    total = w[0] * speeds[0] * speeds[0]
    for wc, sc in zip(w[1:], speeds[1:]):
        total = total + wc * sc * sc
    return np.sqrt(total)


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


def _advance(brake: BrakeRows, v_block: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """BrakeBlock.advance for the rows the block moves and every robot (p, N), braking from `speed`
    (the block's braking speed). At rest s_b = 0, and every branch below gives 0 as the scalar code
    does; a block at rest braking from the others' energy takes every direction."""
    block, norms = brake.block, brake.norms
    reach = _distance(block, speed)
    full = norms * reach
    if block.deflection >= math.pi:
        return full
    own = _speed(v_block)
    with np.errstate(divide="ignore", invalid="ignore"):           # at rest: s_b = 0 below
        cosine = _dot(brake.parts, v_block) / (norms * own)
    cosine = np.where(cosine < 1.0, cosine, 1.0)                       # min(1.0, ·)
    cosine = np.where(cosine > -1.0, cosine, -1.0)                     # max(−1.0, ·)
    cos_d, sin_d = block.cone
    with np.errstate(invalid="ignore"):                                 # at rest: s_b = 0 below
        turned = cosine * cos_d + np.sqrt(1.0 - cosine * cosine) * sin_d
    cone = np.where(cosine >= cos_d, full, np.where(turned > 0.0, full * turned, 0.0))
    return np.where(own <= 0.0, full, cone)
