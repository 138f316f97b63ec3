"""The batched governor and speed-aware rows, compiled robot by robot (numba).

`BackupTable.govern` and `BackupTable.speed_aware_rows` (backup.py of this package) spend their
time in a few hundred numpy operations per probe, each over the robots that need it: about
1.3 µs per robot and probe on a 4096-robot batch, ten probes a robot in a root search. The same
arithmetic written per robot and compiled keeps every intermediate in registers.

`CompiledBackup.of(table)` compiles for the omnidirectional robot's stop (backup.omni_backup: two
brake blocks, the translation (x, y) and the yaw ψ, each braking in any direction (deflection π),
with the hold deviation `OmniHoldDeviation`), and returns None for any other model or when numba
is not installed (the `montecarlo` extra) — the caller then keeps the numpy code. Every function
below is the numpy one of backup.py written for one robot, operation for operation and in its
order of summation, so the two agree to rounding and decide alike (np.max/np.min propagate NaN:
so do `_largest`, `_least`). tests/test_compiled_backup.py holds them together on random states,
slacks and sets.

Loops over robots are serial: the Monte-Carlo runs one single-threaded worker per core.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..backup import _INSIDE, _LAMBDA_RESOLUTION
from ..models.omni_robot_stop import OmniHoldDeviation, hold_deviation_bounds

try:                                    # an optional dependency: the `montecarlo` extra
    import numba
except ImportError:                     # pragma: no cover - exercised where numba is absent
    numba = None


def available() -> bool:
    """Whether numba is installed (then the omni robot's governor runs compiled)."""
    return numba is not None


# the parameter vector's slots (`_params`)
_COUL, _VISC, _CREEP, _EW, _HAS_EW = 0, 2, 4, 6, 10
_HOLD, _DELTA, _EXTRA, _RHO, _ITER, _RES, _SIZE = 12, 13, 14, 15, 16, 17, 18


@dataclass(frozen=True)
class CompiledBackup:
    """A BackupTable's rows and the omni robot's stop, as the compiled kernels take them."""

    row_K: np.ndarray          # (P, 3)
    row_T: np.ndarray          # (P,)
    norms: np.ndarray          # (2, P): |K_j,b| per block
    region_rows: np.ndarray    # (R, longest) the polytopes' rows, padded with −1
    region_len: np.ndarray     # (R,)
    region_norms: np.ndarray   # (R, 2)
    params: np.ndarray         # (_SIZE,) the blocks' and the model's constants

    @staticmethod
    def of(table) -> "CompiledBackup | None":
        """The compiled form of `table` (a BackupTable), or None where it has none: numba missing, or a
        model other than the omni robot's (backup.omni_backup's two blocks, deflection π, its hold
        deviation)."""
        model = table.model
        blocks = model.blocks
        if numba is None or not isinstance(model.hold_deviation, OmniHoldDeviation) or table.row_K.shape[1] != 3:
            return None
        if len(blocks) != 2 or tuple(blocks[0].axes) != (0, 1) or tuple(blocks[1].axes) != (2,):
            return None
        if any(b.deflection < math.pi or (b.energy_weights and len(b.energy_weights) != 2) for b in blocks):
            return None
        p = np.zeros(_SIZE)
        for b, block in enumerate(blocks):
            p[_COUL + b], p[_VISC + b], p[_CREEP + b] = block.coulomb, block.viscous, block.creep
            if block.energy_weights:
                p[_EW + 2 * b], p[_EW + 2 * b + 1] = block.energy_weights
                p[_HAS_EW + b] = 1.0
        p[_HOLD], p[_DELTA], p[_EXTRA] = model.hold, model.margin, model.extra_deceleration
        p[_RHO], p[_ITER], p[_RES] = model.hold_deviation.wheel_share, model.iterations, _LAMBDA_RESOLUTION
        longest = max(len(r) for r in table.region_rows)
        rows = np.full((len(table.region_rows), longest), -1, np.int64)
        for r, members in enumerate(table.region_rows):
            rows[r, :len(members)] = members
        norms = np.vstack([n[:, 0] for n in table.row_norms])
        return CompiledBackup(np.ascontiguousarray(table.row_K, float), np.ascontiguousarray(table.row_T[:, 0]),
                              np.ascontiguousarray(norms), rows, np.array([len(r) for r in table.region_rows]),
                              np.ascontiguousarray(table.region_norms, float), p)

    def _tables(self):
        return self.row_K, self.row_T, self.norms, self.region_rows, self.region_len, self.region_norms, self.params

    def govern(self, theta, q, v, u, dt: float, slack=None, hint=None):
        """BackupTable.govern: (the command to send (n, N), λ (N,))."""
        N = q.shape[1]
        sl, has = _slack(slack, N)
        sent, share = np.empty((3, N)), np.empty(N)
        _govern_all(self._tables(), _f(theta), _f(q), _f(v), _f(u), float(dt), sl, has,
                    np.zeros(N) if hint is None else _f(hint), sent, share)
        return sent, share

    def speed_aware_rows(self, x, v, far: float, a=None, slack=None):
        """BackupTable.speed_aware_rows on the row values x (P, N)."""
        N = v.shape[1]
        sl, has = _slack(slack, N)
        out = np.empty_like(x)
        held = np.zeros((3, N)) if a is None else _f(a)
        _speed_aware_all(self._tables(), np.ascontiguousarray(x, float), _f(v), float(far), held, a is not None,
                         sl, has, out)
        return out


def _f(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float)


def _slack(slack, N: int):
    """(2, N) the slack per block and robot (a float or (N,) each), and whether there is one."""
    if slack is None:
        return np.zeros((2, N)), False
    out = np.empty((2, N))
    for b, e in enumerate(slack):
        out[b] = e
    return out, True


def _jit(fn):
    return numba.njit(cache=True, error_model="numpy")(fn) if numba is not None else fn


# ----- one robot: the blocks' speeds and stops ---------------------------------------------------------
@_jit
def _speeds(x0, x1, x2):
    """|x_b| of the translation (x0, x1) and the yaw (x2): backup._speed's sums."""
    total = x0 * x0
    total = total + x1 * x1
    return math.sqrt(total), math.sqrt(x2 * x2)


@_jit
def _braking_speed(p, b, s0, s1):
    """BrakeBlock.braking_speed: √(Σ_c w_c s_c²), or the block's own speed without weights."""
    if p[_HAS_EW + b] == 0.0:
        return s0 if b == 0 else s1
    total = p[_EW + 2 * b] * s0 * s0
    total = total + p[_EW + 2 * b + 1] * s1 * s1
    return math.sqrt(total)


@_jit
def _distance(p, b, speed):
    """BrakeBlock.distance: s_b(speed), the braked path to rest, plus the creep."""
    a, k = p[_COUL + b], p[_VISC + b]
    out = speed * speed / (2.0 * a)
    if k > 0.0:
        closed = speed / k - (a / (k * k)) * math.log1p(k * speed / a)
        if not (k * speed < 1e-6 * a):
            out = closed
    out = out + p[_CREEP + b]
    return 0.0 if speed <= 0.0 else out


@_jit
def _fallback_decelerations(p, s0, s1):
    """backup._fallback_decelerations: a_c + k S_b + a_extra, or s_b / T_w when gentler."""
    hold = p[_HOLD]
    d0 = p[_COUL] + p[_VISC] * _braking_speed(p, 0, s0, s1) + p[_EXTRA]
    d1 = p[_COUL + 1] + p[_VISC + 1] * _braking_speed(p, 1, s0, s1) + p[_EXTRA]
    if hold > 0.0:
        stop = s0 / hold
        d0 = stop if stop < d0 else d0
        stop = s1 / hold
        d1 = stop if stop < d1 else d1
    return d0, d1


_deviation_bounds = _jit(hold_deviation_bounds)


@_jit
def _deviation(p, s, w, alpha, beta, T):
    """OmniHoldDeviation.by_block((s, w), (α, β), T): (x_t, x_ψ, y_t, y_ψ)."""
    x, y = _deviation_bounds(p[_RHO], s, w, alpha, beta, T)
    return x, 0.0 * x, y, 0.0 * y


@_jit
def _spread(p, s, w, e, f, given):
    """OmniHoldDeviation.acceleration_spread, or zeros without a slack (`given` false)."""
    if not given:
        return 0.0, 0.0
    spread = p[_RHO] * (f * (s + e) + w * e)
    return spread, 0.0 * spread


@_jit
def _eps(s0, s1, e0, e1, given):
    """backup's slack per block: ε_b (+ 0·s_b, as the numpy code adds), zeros without one."""
    if not given:
        return 0.0, 0.0
    return e0 + 0.0 * s0, e1 + 0.0 * s1


@_jit
def _state_head(p, s0, s1, e0, e1, given, estimated):
    """BackupTable._state_head: (ε, η, x, the braking speeds' spread), two blocks each."""
    T = p[_HOLD]
    eps0, eps1 = _eps(s0, s1, e0, e1, given)
    eta0, eta1 = _spread(p, s0, s1, e0, e1, given and estimated)
    top0, top1 = s0 + eps0, s1 + eps1
    f0, f1 = _fallback_decelerations(p, top0, top1)
    dq0, dq1, dv0, dv1 = _deviation(p, top0, top1, f0 + eta0, f1 + eta1, T)
    return eps0, eps1, eta0, eta1, dq0, dq1, eps0 + eta0 * T + dv0, eps1 + eta1 * T + dv1


@_jit
def _command_head(p, s0, s1, h0, h1, e0, e1, given):
    """BackupTable._command_head for block accelerations (bounds) h."""
    T = p[_HOLD]
    eps0, eps1 = _eps(s0, s1, e0, e1, given)
    eta0, eta1 = _spread(p, s0, s1, e0, e1, given)
    dq0, dq1, dv0, dv1 = _deviation(p, s0 + eps0, s1 + eps1, eta0 + h0, eta1 + h1, T)
    return eps0, eps1, eta0, eta1, dq0, dq1, eps0 + eta0 * T + dv0, eps1 + eta1 * T + dv1


# ----- one robot: reaches (P,) -------------------------------------------------------------------------
@_jit
def _add_braking(tables, p, s0, s1, spread0, spread1, reach):
    """BackupTable._add_uncertain_braking (deflection π): + |K_j,b| s_b(S_b) from speeds s_b + spread_b."""
    norms = tables[2]
    t0, t1 = s0 + spread0, s1 + spread1
    full0 = _distance(p, 0, _braking_speed(p, 0, t0, t1))
    full1 = _distance(p, 1, _braking_speed(p, 1, t0, t1))
    for j in range(reach.shape[0]):
        if norms[0, j] > 0.0:
            reach[j] += norms[0, j] * full0
        if norms[1, j] > 0.0:
            reach[j] += norms[1, j] * full1


@_jit
def _state_reach(tables, v0, v1, v2, head, reach):
    """BackupTable._uncertain_state_reach with its head (`_state_head`'s eight terms), into `reach`."""
    K, norms, p = tables[0], tables[2], tables[6]
    T = p[_HOLD]
    eps0, eps1, eta0, eta1, dq0, dq1, sp0, sp1 = head
    for j in range(reach.shape[0]):
        r = 0.0
        n = norms[0, j]
        if n > 0.0:
            w = K[j, 0] * v0
            w += K[j, 1] * v1
            r = 0.0 + ((0.0 if 0.0 > w else w) + n * eps0) * T + 0.5 * n * eta0 * T * T + n * dq0
        n = norms[1, j]
        if n > 0.0:
            w = K[j, 2] * v2
            r += ((0.0 if 0.0 > w else w) + n * eps1) * T + 0.5 * n * eta1 * T * T + n * dq1
        reach[j] = r
    s0, s1 = _speeds(v0, v1, v2)
    _add_braking(tables, p, s0, s1, sp0, sp1, reach)


@_jit
def _held_advance(w, alpha, T):
    """backup's largest w t + ½αt² over t ∈ [0, T] and 0."""
    advance = w * T + 0.5 * alpha * T * T
    advance = 0.0 if 0.0 > advance else advance
    if not alpha < 0.0:                # not turning: the divisions below cannot matter
        return advance
    ratio = -w / alpha
    peak = -w * w / (2.0 * alpha)
    if 0.0 < ratio and ratio < T and peak > advance:
        return peak
    return advance


@_jit
def _command_reach(tables, v0, v1, v2, a0, a1, a2, head, reach):
    """BackupTable._uncertain_command_reach with its head (`_command_head`'s eight terms), into `reach`."""
    K, norms, p = tables[0], tables[2], tables[6]
    T = p[_HOLD]
    eps0, eps1, eta0, eta1, dq0, dq1, sp0, sp1 = head
    for j in range(reach.shape[0]):
        w = K[j, 0] * v0
        w += K[j, 1] * v1
        w += K[j, 2] * v2
        alpha = K[j, 0] * a0
        alpha += K[j, 1] * a1
        alpha += K[j, 2] * a2
        n0, n1 = norms[0, j], norms[1, j]
        w += n0 * eps0
        alpha += n0 * eta0
        held = 0.0 + (n0 * dq0 if n0 > 0.0 else 0.0)
        w += n1 * eps1
        alpha += n1 * eta1
        held += n1 * dq1 if n1 > 0.0 else 0.0
        reach[j] = _held_advance(w, alpha, T) + held
    e0, e1, e2 = v0 + a0 * T, v1 + a1 * T, v2 + a2 * T
    s0, s1 = _speeds(e0, e1, e2)
    _add_braking(tables, p, s0, s1, sp0, sp1, reach)


# ----- one robot: margins ------------------------------------------------------------------------------
@_jit
def _values(tables, q0, q1, q2, x):
    """x_j = k_j q + t_j, summed as backup._margin sums them."""
    K, T = tables[0], tables[1]
    for j in range(x.shape[0]):
        s = K[j, 0] * q0
        s += K[j, 1] * q1
        s += K[j, 2] * q2
        x[j] = s + T[j]


@_jit
def _largest(values, rows, count):
    """np.max over values[rows[:count]] (NaN if any is)."""
    best = values[rows[0]]
    for i in range(1, count):
        x = values[rows[i]]
        if x != x or best != best:
            return math.nan
        if x > best:
            best = x
    return best


@_jit
def _least(values, rows, count):
    """np.min over values[rows[:count]] (NaN if any is)."""
    best = values[rows[0]]
    for i in range(1, count):
        x = values[rows[i]]
        if x != x or best != best:
            return math.nan
        if x < best:
            best = x
    return best


@_jit
def _margin(tables, x, reach, skip, far, use_skip, value):
    """BackupTable.margin: max over the polytopes containing q of min_j −(x_j + reach_j), −inf in none;
    with `use_skip`, the rows where `skip` (P,) is nonzero count as `far`. `value`: scratch (P,)."""
    rows, count = tables[3], tables[4]
    for j in range(x.shape[0]):
        value[j] = far[j] if (use_skip and skip[j] != 0.0) else -(x[j] + reach[j])
    best = -math.inf
    for r in range(rows.shape[0]):
        inside = _largest(x, rows[r], count[r]) < 0.0
        least = _least(value, rows[r], count[r])
        if inside and least > best:
            best = least
    return best


@_jit
def _block_bounds(p, dt, s0, s1, h0, h1, e0, e1, given):
    """BackupTable._block_bounds (with the hold deviation) from block speeds s, acceleration bounds h."""
    hold = p[_HOLD]
    T = hold if not (dt > hold) else dt
    eps0, eps1 = _eps(s0, s1, e0, e1, given)
    eta0, eta1 = _spread(p, s0, s1, e0, e1, given)
    acc0, acc1 = eta0 + h0, eta1 + h1
    dq0, dq1, dv0, dv1 = _deviation(p, s0 + eps0, s1 + eps1, acc0, acc1, T)
    top0, top1 = s0 + eps0 + acc0 * T + dv0, s1 + eps1 + acc1 * T + dv1
    et0, et1 = _spread(p, top0, top1, top0, top1, given)
    f0, f1 = _fallback_decelerations(p, top0, top1)
    dg0, dg1, yg0, yg1 = _deviation(p, top0, top1, f0 + et0, f1 + et1, hold)
    end0, end1 = top0 + et0 * T + yg0, top1 + et1 * T + yg1
    c0 = top0 * (T + dt) + dq0 + 0.5 * et0 * T * T + dg0 + _distance(p, 0, _braking_speed(p, 0, end0, end1))
    c1 = top1 * (T + dt) + dq1 + 0.5 * et1 * T * T + dg1 + _distance(p, 1, _braking_speed(p, 1, end0, end1))
    return c0, c1


@_jit
def _crude(tables, c0, c1, out):
    norms = tables[2]
    for j in range(out.shape[0]):
        out[j] = norms[0, j] * c0 + norms[1, j] * c1


@_jit
def _clearly_safe(tables, x, c0, c1):
    """BackupTable._clearly_safe from the block bounds (c0, c1)."""
    rows, count, rn = tables[3], tables[4], tables[5]
    best = -math.inf
    for r in range(rows.shape[0]):
        room = -_largest(x, rows[r], count[r])
        loss = rn[r, 0] * c0
        loss = loss + rn[r, 1] * c1
        value = room - loss
        if room > 0.0 and value > best:
            best = value
    return best


@_jit
def _uncertain_next(p, x1, norms, v0, v1, v2, dt, e0, e1, given, h0, h1):
    """BackupTable._uncertain_next: x1 moved in place; returns the next state's slack (two blocks)."""
    s0, s1 = _speeds(v0, v1, v2)
    eps0, eps1 = _eps(s0, s1, e0, e1, given)
    eta0, eta1 = _spread(p, s0, s1, e0, e1, given)
    dq0, dq1, dv0, dv1 = _deviation(p, s0 + eps0, s1 + eps1, eta0 + h0, eta1 + h1, dt)
    m0 = eps0 * dt + 0.5 * eta0 * dt * dt + dq0
    m1 = eps1 * dt + 0.5 * eta1 * dt * dt + dq1
    for j in range(x1.shape[0]):
        n0, n1 = norms[0, j], norms[1, j]
        x1[j] = x1[j] + (n0 * m0 if n0 > 0.0 else 0.0)
        x1[j] = x1[j] + (n1 * m1 if n1 > 0.0 else 0.0)
    return eps0 + eta0 * dt + dv0, eps1 + eta1 * dt + dv1


@_jit
def _merit(tables, q, v, x, a0, a1, a2, dt, e0, e1, given, bound0, bound1, use_bounds, scratch):
    """BackupTable._merit for one robot and acceleration a; the block bounds that sort the rows are
    (bound0, bound1) when `use_bounds` (`_segment`'s), else a's own. `scratch`: (6, P)."""
    norms, p = tables[2], tables[6]
    delta = p[_DELTA]
    crude, reach, far, x1, value, skip = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4], scratch[5]
    v0, v1, v2 = v[0], v[1], v[2]
    s0, s1 = _speeds(v0, v1, v2)
    h0, h1 = _speeds(a0, a1, a2)
    if use_bounds:
        _crude(tables, bound0, bound1, crude)
    else:
        c0, c1 = _block_bounds(p, dt, s0, s1, h0, h1, e0, e1, given)
        _crude(tables, c0, c1, crude)
    _command_reach(tables, v0, v1, v2, a0, a1, a2, _command_head(p, s0, s1, h0, h1, e0, e1, given), reach)
    P = x.shape[0]
    for j in range(P):
        far[j] = -(x[j] + crude[j])
        skip[j] = 0.0 if (x[j] + crude[j] > -delta) else 1.0
    command = _margin(tables, x, reach, skip, far, True, value)
    if command < delta:
        return command - delta
    _values(tables, q[0] + v0 * dt + 0.5 * a0 * dt * dt, q[1] + v1 * dt + 0.5 * a1 * dt * dt,
            q[2] + v2 * dt + 0.5 * a2 * dt * dt, x1)
    n0, n1, n2 = v0 + a0 * dt, v1 + a1 * dt, v2 + a2 * dt
    l0, l1 = _uncertain_next(p, x1, norms, v0, v1, v2, dt, e0, e1, given, h0, h1)
    t0, t1 = _speeds(n0, n1, n2)
    _state_reach(tables, n0, n1, n2, _state_head(p, t0, t1, l0, l1, True, given), reach)
    for j in range(P):
        if skip[j] != 0.0:
            x1[j] = -1.0                   # a row that cannot decide is inside
    state = _margin(tables, x1, reach, skip, far, True, value)
    return (state if state < command else command) - delta


@_jit
def _segment(p, v, a0, a1, a2, g0, g1, g2, dt, e0, e1, given):
    """BackupTable._segment for one robot: the block bounds at the segment's largest block norms."""
    nx0, nx1 = _speeds(a0, a1, a2)
    ny0, ny1 = _speeds(g0, g1, g2)
    held0 = ny0 if ny0 > nx0 else nx0
    held1 = ny1 if ny1 > nx1 else nx1
    s0, s1 = _speeds(v[0], v[1], v[2])
    return _block_bounds(p, dt, s0, s1, held0, held1, e0, e1, given)


@_jit
def _next_margin(tables, q, v, a0, a1, a2, dt, e0, e1, given, scratch):
    """backup._next_margin: the backup margin of the state one period on under a."""
    p = tables[6]
    x1, reach, value = scratch[3], scratch[1], scratch[4]
    _values(tables, q[0] + v[0] * dt + 0.5 * a0 * dt * dt, q[1] + v[1] * dt + 0.5 * a1 * dt * dt,
            q[2] + v[2] * dt + 0.5 * a2 * dt * dt, x1)
    n0, n1, n2 = v[0] + a0 * dt, v[1] + a1 * dt, v[2] + a2 * dt
    s0, s1 = _speeds(n0, n1, n2)
    _state_reach(tables, n0, n1, n2, _state_head(p, s0, s1, e0, e1, given, True), reach)
    return _margin(tables, x1, reach, scratch[5], scratch[2], False, value)


@_jit
def _command_margin(tables, v, x, a0, a1, a2, e0, e1, given, scratch):
    """BackupTable.command_margin for one robot (x: its row values)."""
    p = tables[6]
    reach, value = scratch[1], scratch[4]
    s0, s1 = _speeds(v[0], v[1], v[2])
    h0, h1 = _speeds(a0, a1, a2)
    _command_reach(tables, v[0], v[1], v[2], a0, a1, a2, _command_head(p, s0, s1, h0, h1, e0, e1, given), reach)
    return _margin(tables, x, reach, scratch[5], scratch[2], False, value)


@_jit
def _fallback(p, v0, v1, v2):
    """BackupModel.fallback_acceleration a_g for one robot."""
    s0, s1 = _speeds(v0, v1, v2)
    d0, d1 = _fallback_decelerations(p, s0, s1)
    if s0 <= 0.0:
        g0 = g1 = 0.0
    else:
        g0, g1 = -d0 * v0 / s0, -d0 * v1 / s0
    g2 = 0.0 if s1 <= 0.0 else -d1 * v2 / s1
    return g0, g1, g2


@_jit
def _root(tables, q, v, x, a, g, f_lo, f_hi, dt, e0, e1, given, seg, scratch, hint):
    """backup._root: regula falsi with the Illinois rule on [0, 1], probes on the 2⁻¹² grid, after the
    hint and its neighbour when 0 < hint < 1; returns hi."""
    p = tables[6]
    res = p[_RES]
    st0, st1, st2 = g[0] - a[0], g[1] - a[1], g[2] - a[2]
    lo, hi, kept, probes = 0.0, 1.0, 0.0, int(p[_ITER])
    if 0.0 < hint and hint < 1.0:
        lam = np.rint(hint / res) * res
        lam = lam if lam > lo + res else lo + res
        lam = lam if lam < hi - res else hi - res
        m = 0.0
        for probe in range(2):
            if probe == 1:
                if hi - lo <= res:
                    break
                lam = hi - res if m >= 0.0 else lo + res
            m = _merit(tables, q, v, x, a[0] + lam * st0, a[1] + lam * st1, a[2] + lam * st2, dt, e0, e1, given,
                       seg[0], seg[1], True, scratch)
            probes -= 1
            if m >= 0.0:
                hi, f_hi = lam, m
            else:
                lo, f_lo = lam, m
    for _ in range(probes):
        if hi - lo <= res:
            break
        lam = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (lo < lam and lam < hi):
            lam = 0.5 * (lo + hi)
        lam = np.rint(lam / res) * res
        lam = lam if lam > lo + res else lo + res
        lam = lam if lam < hi - res else hi - res
        m = _merit(tables, q, v, x, a[0] + lam * st0, a[1] + lam * st1, a[2] + lam * st2, dt, e0, e1, given,
                   seg[0], seg[1], True, scratch)
        if m >= 0.0:
            hi, f_hi = lam, m
            f_lo = 0.5 * f_lo if kept < 0 else f_lo
            kept = -1.0
        else:
            lo, f_lo = lam, m
            f_hi = 0.5 * f_hi if kept > 0 else f_hi
            kept = 1.0
    while hi - lo > res:               # the chords stalled: bisect what is left (backup._root)
        lam = np.rint(0.5 * (lo + hi) / res) * res
        lam = lam if lam > lo + res else lo + res
        lam = lam if lam < hi - res else hi - res
        m = _merit(tables, q, v, x, a[0] + lam * st0, a[1] + lam * st1, a[2] + lam * st2, dt, e0, e1, given,
                   seg[0], seg[1], True, scratch)
        if m >= 0.0:
            hi = lam
        else:
            lo = lam
    return hi


@_jit
def _govern_all(tables, theta, q, v, u, dt, slack, given, hint, sent, share):
    """BackupTable.govern for every robot (columns), into `sent` (3, N) and `share` (N,); `hint` (N,):
    each robot's last λ."""
    p = tables[6]
    delta = p[_DELTA]
    P = tables[0].shape[0]
    scratch = np.empty((6, P))
    x = np.empty(P)
    qi, vi = np.empty(3), np.empty(3)
    a, g = np.empty(3), np.empty(3)
    for i in range(q.shape[1]):
        for c in range(3):
            qi[c], vi[c], sent[c, i] = q[c, i], v[c, i], u[c, i]
        share[i] = 0.0
        m1, m3, ath = theta[0, i], theta[1, i], theta[2, i]
        e0, e1 = slack[0, i], slack[1, i]
        a_psi = ath * vi[2]
        a[0] = (u[0, i] - a_psi * vi[1]) / m1
        a[1] = (u[1, i] + a_psi * vi[0]) / m1
        a[2] = u[2, i] / m3
        _values(tables, qi[0], qi[1], qi[2], x)
        s0, s1 = _speeds(vi[0], vi[1], vi[2])
        h0, h1 = _speeds(a[0], a[1], a[2])
        c0, c1 = _block_bounds(p, dt, s0, s1, h0, h1, e0, e1, given)
        if _clearly_safe(tables, x, c0, c1) >= delta:
            continue
        m_u = _merit(tables, qi, vi, x, a[0], a[1], a[2], dt, e0, e1, given, 0.0, 0.0, False, scratch)
        if m_u >= 0.0:
            continue
        g[0], g[1], g[2] = _fallback(p, vi[0], vi[1], vi[2])
        m_g = _merit(tables, qi, vi, x, g[0], g[1], g[2], dt, e0, e1, given, 0.0, 0.0, False, scratch)
        psi = vi[2]
        u_g0 = g[0] * m1 + psi * vi[1] * ath                 # regressor_times(v, v, a_g, θ)
        u_g1 = g[1] * m1 - psi * vi[0] * ath
        u_g2 = g[2] * m3
        if not (m_g >= 0.0):             # outside the envelope: u or u_g as backup.govern chooses
            after_u = _next_margin(tables, qi, vi, a[0], a[1], a[2], dt, e0, e1, given, scratch)
            after_g = _next_margin(tables, qi, vi, g[0], g[1], g[2], dt, e0, e1, given, scratch)
            held_g = _command_margin(tables, vi, x, g[0], g[1], g[2], e0, e1, given, scratch)
            held_u = _command_margin(tables, vi, x, a[0], a[1], a[2], e0, e1, given, scratch)
            if not (after_u >= after_g and (held_u >= delta or not (held_g >= delta))):
                sent[0, i], sent[1, i], sent[2, i] = u_g0, u_g1, u_g2
                share[i] = 1.0
            continue
        seg = _segment(p, vi, a[0], a[1], a[2], g[0], g[1], g[2], dt, e0, e1, given)
        hi = _root(tables, qi, vi, x, a, g, m_u, m_g, dt, e0, e1, given, seg, scratch, hint[i])
        sent[0, i] = u[0, i] + hi * (u_g0 - u[0, i])
        sent[1, i] = u[1, i] + hi * (u_g1 - u[1, i])
        sent[2, i] = u[2, i] + hi * (u_g2 - u[2, i])
        share[i] = hi


@_jit
def _speed_aware_all(tables, x, v, far, held, use_held, slack, given, out):
    """BackupTable.speed_aware_rows for every robot (columns of x (P, N)), into `out`."""
    p = tables[6]
    P = x.shape[0]
    crude, reach = np.empty(P), np.empty(P)
    for i in range(x.shape[1]):
        v0, v1, v2 = v[0, i], v[1, i], v[2, i]
        e0, e1 = slack[0, i], slack[1, i]
        s0, s1 = _speeds(v0, v1, v2)
        h0, h1 = _speeds(held[0, i], held[1, i], held[2, i])
        c0, c1 = _block_bounds(p, 0.0, s0, s1, h0, h1, e0, e1, given)
        _crude(tables, c0, c1, crude)
        near = False
        for j in range(P):
            out[j, i] = x[j, i]
            if x[j, i] < 0.0 and x[j, i] + crude[j] > -far:
                near = True
        if not near:
            continue
        if use_held:
            _command_reach(tables, v0, v1, v2, held[0, i], held[1, i], held[2, i],
                           _command_head(p, s0, s1, h0, h1, e0, e1, given), reach)
        else:
            _state_reach(tables, v0, v1, v2, _state_head(p, s0, s1, e0, e1, given, True), reach)
        for j in range(P):
            xj = x[j, i]
            if xj < 0.0 and xj + crude[j] > -far:
                moved = xj + reach[j]
                out[j, i] = -_INSIDE if -_INSIDE < moved else moved
