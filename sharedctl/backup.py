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

`govern` returns the command to send: u itself when it is backup-safe, else the point of the
segment from u to the fallback u_g closest to u that is; when not even u_g is (the state is
outside the envelope: no stop from here ends δ inside), u unchanged — the law's barrier brakes
harder than u_g. u_g decelerates each block along −v_b at
max(a_c + k|v_b| + a_extra, …) — harder than the brakes — or stops it within T_w at low speed; under
u_g the state's backup margin never decreases, so u_g is always available once the state is
backup-safe (docs/control.md §10 for the argument). Pure: no clocks, no I/O.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BrakeBlock:
    """Coordinates `axes` sharing one speed; the unpowered deceleration is at least a_c + k·speed."""

    axes: tuple[int, ...]
    coulomb: float          # a_c (units/s²)
    viscous: float          # k (1/s)
    deflection: float = math.pi   # the most the braked velocity turns from its start (rad; π: any)
    creep: float = 0.0            # path added to every stop: a brake that fades near rest (m)

    def __post_init__(self):
        if not (self.coulomb > 0.0 and self.viscous >= 0.0 and math.isfinite(self.coulomb + self.viscous)
                and 0.0 <= self.deflection <= math.pi):
            raise ValueError("a brake block needs a_c > 0 and k >= 0, finite, and a deflection in [0, π]")

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
        out = []
        for k, n in rows:
            if n <= 0.0:
                out.append(0.0)
                continue
            cosine = max(-1.0, min(1.0, _dot(k, v_block) / (n * speed)))
            angle = max(math.acos(cosine) - self.deflection, 0.0)
            out.append(n * reach * math.cos(angle) if angle < _HALF_PI else 0.0)
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
    bisections: int = 12

    def __post_init__(self):
        if not (self.hold >= 0.0 and self.margin >= 0.0 and self.extra_deceleration > 0.0):
            raise ValueError("backup: hold >= 0, margin >= 0 and extra_deceleration > 0 are required")

    # ----- reach: how far each row may still move towards its face -------------------------
    def state_reach(self, K, v) -> list[float]:
        """(K_j v)⁺ T_w + Σ_b advance_b for every row of K: the fallback held T_w (it decelerates
        along −v, so a row advances at most (K_j v)⁺ T_w), then the brakes from v."""
        return self._state_reach(_rows_of(self, K), _as_floats(v))

    def command_reach(self, K, v, a) -> list[float]:
        """Holding the acceleration a for T_w (each row's largest advance, exact for constant a), then
        braking from v + a T_w."""
        return self._command_reach(_rows_of(self, K), _as_floats(v), _as_floats(a))

    def state_margin(self, feasible, q, v) -> float:
        """max over the polytopes containing q of min_j −(x_j + reach_j): ≥ δ means backup-safe
        (−inf when no polytope contains q)."""
        v = _as_floats(v)
        return self._margin(feasible, q, lambda rows: self._state_reach(rows, v))

    def command_margin(self, feasible, q, v, a) -> float:
        v, a = _as_floats(v), _as_floats(a)
        return self._margin(feasible, q, lambda rows: self._command_reach(rows, v, a))

    def _margin(self, feasible, q, reach_of) -> float:
        q = _as_floats(q)
        best = -math.inf
        for rows in _region_rows(self, feasible):
            x = [_dot(k, q) + t for k, t, _ in rows]
            if max(x) < 0.0:
                best = max(best, min(-(xj + rj) for xj, rj in zip(x, reach_of(rows))))
        return best

    def _state_reach(self, rows, v) -> list[float]:
        T = self.hold
        reach = [max(_dot(k, v), 0.0) * T for k, _, _ in rows]
        return self._add_braking(rows, v, reach)

    def _command_reach(self, rows, v, a) -> list[float]:
        T = self.hold
        reach = []
        for k, _, _ in rows:
            w = _dot(k, v)
            alpha = _dot(k, a)
            advance = max(w * T + 0.5 * alpha * T * T, 0.0)
            if alpha < 0.0 and 0.0 < -w / alpha < T:
                advance = max(advance, -w * w / (2.0 * alpha))
            reach.append(advance)
        return self._add_braking(rows, [vj + aj * T for vj, aj in zip(v, a)], reach)

    def _add_braking(self, rows, v_end, reach) -> list[float]:
        for b, block in enumerate(self.blocks):
            extra = block.advance([parts[b] for _, _, parts in rows], [v_end[i] for i in block.axes])
            reach = [r + e for r, e in zip(reach, extra)]
        return reach

    def fallback_acceleration(self, v: np.ndarray) -> np.ndarray:
        """a_g: each block decelerated along −v_b at a_c + k|v_b| + a_extra, or stopped within T_w
        when that is gentler (no reversal during the hold)."""
        a = np.zeros_like(v)
        for block in self.blocks:
            axes = list(block.axes)
            speed = float(np.linalg.norm(v[axes]))
            if speed <= 0.0:
                continue
            decel = block.coulomb + block.viscous * speed + self.extra_deceleration
            if self.hold > 0.0:
                decel = min(decel, speed / self.hold)
            a[axes] = -decel * v[axes] / speed
        return a


@dataclass(frozen=True)
class Governed:
    """What `govern` decided: the command to send and how far it moved from the one asked for."""

    u: np.ndarray
    share: float          # λ ∈ [0, 1]: 0 = the command as asked, 1 = the fallback
    feasible: bool        # False: not even the fallback is backup-safe (it is sent anyway)
    margin: float         # the state's backup margin (m) at this sample


def govern(backup: BackupModel, model, feasible, q: np.ndarray, v: np.ndarray, u: np.ndarray,
           dt: float) -> Governed:
    """The backup-safe command closest to u on the segment u → u_g (bisection on λ).

    Most samples are far from every face for their speed: a bound that needs only each polytope's
    smallest slack (`_clearly_safe`) accepts u there without the row-by-row reaches."""
    q, v, u = np.asarray(q, float), np.asarray(v, float), np.asarray(u, float)
    delta = backup.margin
    a = model.acceleration(q, v, u)
    slack = _clearly_safe(backup, feasible, q, v, a, dt)
    if slack >= delta:
        return Governed(u, 0.0, True, slack)
    state_margin = backup.state_margin(feasible, q, v)

    def acceptable(command, a=None) -> bool:
        a = model.acceleration(q, v, command) if a is None else a
        if backup.command_margin(feasible, q, v, a) < delta:
            return False
        return backup.state_margin(feasible, q + v * dt + 0.5 * a * dt * dt, v + a * dt) >= delta

    if acceptable(u, a):
        return Governed(u, 0.0, True, state_margin)
    a_g = backup.fallback_acceleration(v)
    u_g = model.inverse_dynamics(q, v, a_g)
    if not acceptable(u_g, a_g):
        # outside the envelope (the stop from here cannot end δ inside whatever is sent): the
        # governor has nothing better than the law, whose barrier brakes harder than u_g
        return Governed(u, 0.0, False, state_margin)
    lo, hi = 0.0, 1.0
    for _ in range(backup.bisections):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if acceptable(u + mid * (u_g - u)) else (mid, hi)
    return Governed(u + hi * (u_g - u), hi, True, state_margin)


def _block_bounds(backup: BackupModel, v, a, dt: float) -> list[float]:
    """Per block, C_b = (|v_b| + |a_b| T)(T + dt) + s_b(|v_b| + |a_b| T): no row advances more than
    Σ_b |K_j,b| C_b, neither while a is held T_w then braked, nor over one period plus the stop
    of the state it leads to."""
    T = backup.hold
    bounds = []
    for block in backup.blocks:
        axes = list(block.axes)
        top = float(np.linalg.norm(v[axes])) + float(np.linalg.norm(a[axes])) * T
        bounds.append(top * (T + dt) + block.distance(top))
    return bounds


def _row_norms(backup: BackupModel, feasible) -> list[list[float]]:
    """Per polytope, per block, max_j |K_j,b| (cached on the feasible set)."""
    cache = feasible.__dict__.setdefault("_backup_row_norms", {})
    key = tuple(block.axes for block in backup.blocks)
    if key not in cache:
        cache[key] = [[float(np.max(np.linalg.norm(r.K[:, list(axes)], axis=1))) for axes in key]
                      for r in feasible.regions]
    return cache[key]


def _clearly_safe(backup: BackupModel, feasible, q, v, a, dt: float) -> float:
    """A lower bound of the command's and the next state's backup margin (−inf if q is in no
    polytope): the best containing polytope's slack less Σ_b max_j|K_j,b| C_b."""
    bounds = _block_bounds(backup, v, a, dt)
    best = -math.inf
    for slack, norms in zip(feasible.region_margins(q).tolist(), _row_norms(backup, feasible)):
        if slack > 0.0:
            best = max(best, slack - sum(n * c for n, c in zip(norms, bounds)))
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

    When every row inside stays at or below −`far` even moved by the crude bound of any row's
    reach, the rows are returned unmoved: `far` is the widest band, b2 (Definition 2 classifies a
    row there as safe whether or not it is moved)."""
    values, rates = rows
    v = np.asarray(v, float)
    a_held = np.zeros_like(v) if a is None else np.asarray(a, float)
    crude = sum(n * c for n, c in zip(_all_row_norms(backup, feasible), _block_bounds(backup, v, a_held, 0.0)))
    if all(x >= 0.0 or x + crude <= -far for x in values):
        return rows
    reach = backup.state_reach(feasible.row_matrix, v) if a is None else backup.command_reach(feasible.row_matrix, v, a)
    shifted = [x if x >= 0.0 else min(x + r, -_INSIDE) for x, r in zip(values, reach)]
    return shifted, rates


def _all_row_norms(backup: BackupModel, feasible) -> list[float]:
    return [max(column) for column in zip(*_row_norms(backup, feasible))]

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
    """[(K_j, 0, [(K_j,b, |K_j,b|) per block]) …] for the rows of K, as floats."""
    K = np.asarray(K, float)
    parts = [[(tuple(K[j, list(b.axes)].tolist()), float(np.linalg.norm(K[j, list(b.axes)])))
              for b in backup.blocks] for j in range(K.shape[0])]
    return [(tuple(K[j].tolist()), 0.0, parts[j]) for j in range(K.shape[0])]


def _region_rows(backup: BackupModel, feasible) -> list:
    """Per polytope, its rows as `_rows_of` gives them with T_j in place of 0 (cached on the set)."""
    cache = feasible.__dict__.setdefault("_backup_rows", {})
    key = tuple(b.axes for b in backup.blocks)
    if key not in cache:
        cache[key] = [[(k, float(t), parts) for (k, _, parts), t in zip(_rows_of(backup, r.K), r.T.tolist())]
                      for r in feasible.regions]
    return cache[key]


_HALF_PI = math.pi / 2
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
