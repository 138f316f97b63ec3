"""Backup-safe states: the fail-safe stop ends inside Q_a (docs/control.md §10).

When the controller is lost (killed, hung, its bus gone) every drive holds its last torque until
its watchdog expires, `hold` = T_w seconds, then disarms and its wheel's fail-safe brake stops the
robot. A state is *backup-safe* when that stop, started now, ends inside the admissible set.

The brakes are described per block of coordinates (the omnidirectional robot: the translation
(x, y) and the yaw ψ; `BrakeBlock`): whatever the direction of motion, the unpowered block b
travels at most the path of v dv/dx = −(a_c + kv) from its braking speed S_b,

    s_b(S) = S/k − (a_c/k²) ln(1 + k S/a_c)          (a_c/k²… → S²/(2a_c) as k → 0),

S_b = |v_b| for a block whose brakes are its own; blocks whose brakes are shared (the robot's
wheels brake its translation and its yaw at once) bound their paths by the kinetic energy of all of
them, S_b = √(Σ_c w_b,c |v_c|²) = √(2K/m_b) (`BrakeBlock.energy_weights`;
models/omni_robot_stop.py). A row j of a polytope, K_j q + T_j ≤ 0, moves towards its face by at
most Σ_b |K_j,b| s_b(S_b).

Two checks, both per row of a polytope that contains q (`BackupModel`):

* the **state** (q, v) is backup-safe with margin δ when, for some containing polytope,
  x_j + Σ_b ((K_j,b v_b)⁺ T_w + |K_j,b| s_b(S_b)) ≤ −δ for all its rows — the stop from a command
  that does not speed any block up;
* a **command** u is backup-safe at (q, v) when holding it for T_w (row by row, exactly: constant
  acceleration a = M⁻¹(u − C v − g)) and braking from v + a T_w stays δ inside, and the state one
  control period later (q + v dt + ½a dt², v + a dt) is backup-safe.

A model whose acceleration under a held torque is not constant gives `BackupModel.hold_deviation`,
a bound (x, y) of how far q and q̇ depart from the constant-acceleration motion over a hold of T:
the 2-link arm (M(q), C and g(q) move during the hold; `models/planar_arm_stop.py`) one for all
coordinates, the omnidirectional robot (its drives hold wheel torques, so the world-frame force
turns with the robot; `models/omni_robot_stop.py`) one per block. Then every reach adds
Σ_b |K_j,b| x_b to the hold's advance and brakes from speeds y_b higher, with every block's
deflection taken as π, and the next state's check allows for the period's own deviation.

An uncertain state (output feedback: the observer's v̂ and `BackupModel.observer_error`, per block,
`slack`; predicted over a delay, the position too, `offset`; `uncertain_prediction`) is judged for
every state that close: the hold advances a row by up to Σ_b |K_j,b| ε_b more per second, the
command's acceleration (computed at v) is off by the hold deviation's `acceleration_spread` (the
Coriolis term), and the brakes start faster.

`govern` returns the command to send: u itself when it is backup-safe, else the point of the
segment from u to the fallback u_g closest to u that is; when not even u_g is (the state is
outside the envelope: no stop from here ends δ inside), the one of u and u_g after which the state
one period on has the larger backup margin — but u_g wherever its own stop (held for T_w, then the
brakes) ends δ inside and u's does not. u_g decelerates each block along −v_b at a_c + k S_b +
a_extra — harder than the brakes — or stops it within T_w at low speed; under u_g the state's
backup margin never decreases, so u_g is always available once the state is backup-safe
(docs/control.md §10 for the argument). Pure: no clocks, no I/O.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from .models.omni_robot_stop import OmniStopBounds, energy_weights
from .models.planar_arm_stop import ArmBounds, ArmHoldDeviation


@dataclass(frozen=True)
class BrakeBlock:
    """Coordinates `axes` sharing one speed; the unpowered deceleration is at least a_c + k·speed.

    With `energy_weights` (one per block of the model), the block's braking speed is
    S_b = √(Σ_c w_c |v_c|²) instead of its own |v_b|: blocks braked by shared brakes (the robot's
    wheels) bound their paths by the kinetic energy of all of them (models/omni_robot_stop.py)."""

    axes: tuple[int, ...]
    coulomb: float          # a_c (units/s²)
    viscous: float          # k (1/s)
    deflection: float = math.pi   # the most the braked velocity turns from its start (rad; π: any)
    creep: float = 0.0            # path added to every stop: a brake that fades near rest (m)
    energy_weights: tuple = ()    # w_c per block: S_b² = Σ_c w_c |v_c|²; (): S_b = |v_b|
    cone: tuple = field(init=False, repr=False, compare=False)    # (cos, sin) of the deflection

    def __post_init__(self):
        if not (self.coulomb > 0.0 and self.viscous >= 0.0 and math.isfinite(self.coulomb + self.viscous)
                and 0.0 <= self.deflection <= math.pi):
            raise ValueError("a brake block needs a_c > 0 and k >= 0, finite, and a deflection in [0, π]")
        if not all(w > 0.0 and math.isfinite(w) for w in self.energy_weights):
            raise ValueError("a brake block's energy weights must be positive and finite")
        object.__setattr__(self, "cone", (math.cos(self.deflection), math.sin(self.deflection)))

    def advance(self, rows: list, v_block: list, speed: float | None = None) -> list[float]:
        """For every row (its block part K_j,b and that part's norm, `rows` = [(k, |k|), …]), the
        most its value grows while the brakes stop the block from v_block: s_b(speed) times the
        largest cosine between K_j,b and a velocity within `deflection` of v_b (the displacement
        lies in that cone). `speed`: the braking speed S_b (default |v_b|). On Python floats: a few
        rows, every sample."""
        own = math.sqrt(_dot(v_block, v_block))
        speed = own if speed is None else speed
        if speed <= 0.0:
            return [0.0] * len(rows)
        reach = self.distance(speed)
        if self.deflection >= math.pi or own <= 0.0:
            return [n * reach for _, n in rows]
        # cos(max(angle(K_j,b, v_b) − deflection, 0)), or 0 past a right angle, without acos:
        # with c = cos angle, cos(angle − d) = c cos d + sin angle sin d
        cos_d, sin_d = self.cone
        out = []
        for k, n in rows:
            if n <= 0.0:
                out.append(0.0)
                continue
            cosine = max(-1.0, min(1.0, _dot(k, v_block) / (n * own)))
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

    def braking_speed(self, b: int, speeds: list) -> float:
        """S_b from every block's speed (`speeds`, this block's at index b)."""
        w = self.energy_weights
        if not w:
            return speeds[b]
        total = w[0] * speeds[0] * speeds[0]
        for wc, sc in zip(w[1:], speeds[1:]):
            total = total + wc * sc * sc
        return math.sqrt(total)


@dataclass(frozen=True)
class BackupModel:
    """The fail-safe stop: the last command held `hold` s (T_w), then the brakes of `blocks`."""

    hold: float
    blocks: tuple[BrakeBlock, ...]
    margin: float = 0.01                 # δ (m): how far inside the stop must end
    extra_deceleration: float = 1.0      # a_extra: the fallback brakes this much harder than the brakes
    iterations: int = 12                 # govern's most probes between u and u_g
    # while the torque of acceleration a is held, the motion's departure from q + vt + ½at², nondecreasing in
    # each argument (None: the held acceleration is constant). Either a callable (‖v‖, ‖a‖, T) → (x, y),
    # ‖q(t) − q − vt − ½at²‖ ≤ x and ‖q̇(t) − v − at‖ ≤ y for t ≤ T (one bound for every block), or an object
    # whose by_block(speeds, accelerations, T) → ((x_b …), (y_b …)) bounds each block's part from each
    # block's |v_b| and |a_b|; an object with acceleration_spread(speeds, slacks) may judge uncertain velocities
    hold_deviation: object = None
    # the output-feedback envelope: the observer's error |v_b − v̂_b| is at most this per block (m/s, rad/s);
    # the governor and the speed-aware rows judge every velocity that close to v̂ (): v̂ is taken as exact
    observer_error: tuple = ()

    def __post_init__(self):
        if not (self.hold >= 0.0 and self.margin >= 0.0 and self.extra_deceleration > 0.0):
            raise ValueError("backup: hold >= 0, margin >= 0 and extra_deceleration > 0 are required")
        if any(b.energy_weights and len(b.energy_weights) != len(self.blocks) for b in self.blocks):
            raise ValueError("backup: a block's energy weights need one weight per block")
        if self.observer_error and not (len(self.observer_error) == len(self.blocks) and self.accepts_slack()
                                        and all(e >= 0.0 and math.isfinite(e) for e in self.observer_error)):
            raise ValueError("backup: an observer error needs one finite bound >= 0 per block and a hold deviation "
                             "that bounds the acceleration's spread")

    # ----- reach: how far each row may still move towards its face -------------------------
    def state_reach(self, K, v, slack=None) -> list[float]:
        """Σ_b (K_j,b v_b)⁺ T_w + the brakes' advance for every row of K: the fallback held T_w (it
        decelerates each block along −v_b, so a row advances at most Σ_b (K_j,b v_b)⁺ T_w while it is
        held), then the brakes from v. With `slack` (per block), for every velocity that close to v."""
        return _state_reach(self, _rows_of(self, K), _as_floats(v), _slack(slack, self))

    def command_reach(self, K, v, a, slack=None) -> list[float]:
        """Holding the acceleration a for T_w (each row's largest advance, exact for constant a), then
        braking from v + a T_w."""
        return _command_reach(self, _rows_of(self, K), _as_floats(v), _as_floats(a), _slack(slack, self))

    def state_margin(self, feasible, q, v, slack=None) -> float:
        """max over the polytopes containing q of min_j −(x_j + reach_j): ≥ δ means backup-safe
        (−inf when no polytope contains q)."""
        v, slack = _as_floats(v), _slack(slack, self)
        return self._margin(feasible, q, lambda rows: _state_reach(self, rows, v, slack))

    def command_margin(self, feasible, q, v, a, slack=None) -> float:
        v, a, slack = _as_floats(v), _as_floats(a), _slack(slack, self)
        return self._margin(feasible, q, lambda rows: _command_reach(self, rows, v, a, slack))

    def _margin(self, feasible, q, reach_of) -> float:
        q = _as_floats(q)
        best = -math.inf
        for rows in _region_rows(self, feasible):
            x = [_dot(k, q) + t for k, t, _ in rows]
            if max(x) < 0.0:
                best = max(best, min(-(xj + rj) for xj, rj in zip(x, reach_of(rows))))
        return best

    def fallback_acceleration(self, v: np.ndarray) -> np.ndarray:
        """a_g: each block decelerated along −v_b at a_c + k S_b + a_extra (S_b its braking speed), or
        stopped within T_w when that is gentler (no reversal during the hold)."""
        a = np.zeros_like(v)
        v_list = v.tolist()
        speeds = _block_speeds(self, v_list)
        for block, speed, decel in zip(self.blocks, speeds, _fallback_decelerations(self, speeds)):
            if speed <= 0.0:
                continue
            axes = list(block.axes)
            a[axes] = -decel * v[axes] / speed
        return a

    def accepts_slack(self) -> bool:
        """Can this model judge an uncertain velocity (its hold deviation bounds the acceleration's spread)?"""
        return hasattr(self.hold_deviation, "acceleration_spread")


def _slack(slack, backup: BackupModel | None = None) -> list | None:
    """A caller's slack per block as floats (None: v is exact); only a model that `accepts_slack`
    takes one."""
    if slack is None:
        return None
    if backup is not None and not backup.accepts_slack():
        raise ValueError("backup: this model's hold deviation cannot bound an uncertain velocity's acceleration")
    return [float(e) for e in slack]


def _block_speeds(backup: BackupModel, v: list) -> list[float]:
    """|v_b| per block."""
    return [_norm([v[i] for i in block.axes]) for block in backup.blocks]


def _fallback_decelerations(backup: BackupModel, speeds: list) -> list[float]:
    """The fallback's deceleration per block at block speeds `speeds`: min(a_c + k S_b + a_extra,
    |v_b| / T_w). Nondecreasing in every speed."""
    out = []
    for b, block in enumerate(backup.blocks):
        decel = block.coulomb + block.viscous * block.braking_speed(b, speeds) + backup.extra_deceleration
        if backup.hold > 0.0:
            decel = min(decel, speeds[b] / backup.hold)
        out.append(decel)
    return out


def _deviation(backup: BackupModel, speeds: list, accelerations: list, duration: float) -> tuple[list, list]:
    """(x_b, y_b) per block of `BackupModel.hold_deviation` over `duration` from block speeds and
    accelerations at most `speeds` and `accelerations` (zeros without one)."""
    deviation = backup.hold_deviation
    if deviation is None:
        zeros = [0.0] * len(speeds)
        return zeros, zeros
    by_block = getattr(deviation, "by_block", None)
    if by_block is not None:
        xs, ys = by_block(speeds, accelerations, duration)
        return list(xs), list(ys)
    x, y = deviation(_norm(speeds), _norm(accelerations), duration)
    return [x] * len(speeds), [y] * len(speeds)


def _spread(backup: BackupModel, speeds: list, slack: list | None) -> list[float]:
    """η_b: the most the acceleration of a fixed command moves per block when the velocity moves by
    `slack` from one with block speeds `speeds`. Zeros without a slack, and for a model without
    `acceleration_spread`: its slacks are only the period's own deviation, from a velocity at which
    the next sample computes its commands."""
    spread = getattr(backup.hold_deviation, "acceleration_spread", None)
    if slack is None or spread is None:
        return [0.0] * len(speeds)
    return list(spread(speeds, slack))


def _state_reach(backup: BackupModel, rows, v, slack: list | None = None, offset: list | None = None,
                 estimated: bool = True) -> list[float]:
    """BackupModel.state_reach on rows as `_rows_of` gives them and v as floats; with a hold
    deviation, a slack or an offset, `_uncertain_state_reach`."""
    if backup.hold_deviation is not None or slack is not None or offset is not None:
        return _uncertain_state_reach(backup, rows, v, slack, offset, estimated)
    T = backup.hold
    blocks = [[v[i] for i in block.axes] for block in backup.blocks]
    reach = []
    for _, _, parts in rows:
        advance = max(_dot(parts[0][0], blocks[0]), 0.0) * T
        for b in range(1, len(blocks)):
            advance += max(_dot(parts[b][0], blocks[b]), 0.0) * T
        reach.append(advance)
    return _add_braking(backup, rows, v, reach)


def _command_reach(backup: BackupModel, rows, v, a, slack: list | None = None,
                   offset: list | None = None) -> list[float]:
    """BackupModel.command_reach on rows as `_rows_of` gives them and v, a as floats; with a hold
    deviation, a slack or an offset, `_uncertain_command_reach`."""
    if backup.hold_deviation is not None or slack is not None or offset is not None:
        return _uncertain_command_reach(backup, rows, v, a, slack, offset)
    T = backup.hold
    reach = []
    for k, _, _ in rows:
        reach.append(_hold_advance(_dot(k, v), _dot(k, a), T))
    return _add_braking(backup, rows, [vj + aj * T for vj, aj in zip(v, a)], reach)


def _hold_advance(w: float, alpha: float, T: float) -> float:
    """A row's largest advance over [0, T] at rate w and constant acceleration alpha (exact)."""
    advance = max(w * T + 0.5 * alpha * T * T, 0.0)
    if alpha < 0.0 and 0.0 < -w / alpha < T:
        advance = max(advance, -w * w / (2.0 * alpha))
    return advance


def _add_braking(backup: BackupModel, rows, v_end, reach) -> list[float]:
    """reach + each brake block's advance from v_end, row by row."""
    blocks = [[v_end[i] for i in block.axes] for block in backup.blocks]
    speeds = [_norm(part) for part in blocks]
    for b, block in enumerate(backup.blocks):
        extra = block.advance([parts[b] for _, _, parts in rows], blocks[b], block.braking_speed(b, speeds))
        reach = [r + e for r, e in zip(reach, extra)]
    return reach


# ----- a hold that departs from constant acceleration, an uncertain velocity ----------------
# Each reach is a plan — what depends on (v, a) alone, computed once — applied row by row.
def _uncertain_state_reach(backup: BackupModel, rows, v, slack: list | None, offset: list | None,
                           estimated: bool = True) -> list[float]:
    """The state's reach for every velocity v' with |v'_b − v_b| ≤ ε_b (`slack`, 0 without) and every
    position within p_b (`offset`, 0 without) — which adds Σ_b |K_j,b| p_b to every row — : the
    fallback u_g held T_w — its constant-acceleration part advances a row at most
    Σ_b ((K_j,b v_b)⁺ + |K_j,b| ε_b) T_w + ½|K_j,b| η_b T_w², its deviation at most Σ_b |K_j,b| x_b — then the
    brakes from block speeds |v_b| + ε_b + η_b T_w + y_b (deflection π where any of these is uncertain);
    (x, y) the deviation of a hold of T_w from speeds |v_b| + ε_b at the fallback's deceleration there
    plus η. `estimated`: u_g is computed at v (an estimate), so its acceleration at v' is off by the
    spread η over the slack; else (the slack of the next state under state feedback, whose own
    sample computes u_g at its velocity) η = 0."""
    blocks = _parts(backup, v)
    speeds = [_norm(part) for part in blocks]
    plan = _planned(backup, _state_head(backup, speeds, slack, offset, estimated), blocks, speeds)
    return _state_rows(backup, plan, rows, blocks)


def _parts(backup: BackupModel, v: list) -> list[list[float]]:
    """v's part per block."""
    return [[v[i] for i in block.axes] for block in backup.blocks]


def _state_head(backup: BackupModel, speeds, slack, offset, estimated: bool) -> tuple:
    """What `_state_rows` needs besides the rows, v and the brakes: (T_w, ε, η, x, the spread of the
    braking speeds), from block speeds `speeds` (|v_b|, or bounds of them: every term is nondecreasing
    in them)."""
    T = backup.hold
    n = len(backup.blocks)
    eps = slack if slack is not None else [0.0] * n
    eta = _spread(backup, speeds, slack) if estimated else [0.0] * n
    top = [s + e for s, e in zip(speeds, eps)]
    dq, dv = _deviation(backup, top, [d + h for d, h in zip(_fallback_decelerations(backup, top), eta)], T)
    if offset is not None:
        dq = [x + p for x, p in zip(dq, offset)]
    return T, eps, eta, dq, [e + h * T + y for e, h, y in zip(eps, eta, dv)]


def _planned(backup: BackupModel, head: tuple, blocks, speeds) -> tuple:
    """A head (`_state_head`, `_command_head`) and the brakes' plan from the block velocities `blocks`
    (speeds `speeds`) it spreads: what `_state_rows` and `_command_rows` take."""
    T, eps, eta, dq, spread = head
    return T, eps, eta, dq, _braking_plan(backup, blocks, speeds, spread)


def _state_rows(backup: BackupModel, plan, rows, blocks) -> list[float]:
    T, eps, eta, dq, braking = plan
    n = len(blocks)
    reach = []
    for _, _, parts in rows:
        total = 0.0
        for b in range(n):
            k, norm = parts[b]
            total += (max(_dot(k, blocks[b]), 0.0) + norm * eps[b]) * T + 0.5 * norm * eta[b] * T * T \
                + _scaled(norm, dq[b])
        reach.append(total)
    return _apply_braking(backup, braking, rows, reach)


def _uncertain_command_reach(backup: BackupModel, rows, v, a, slack: list | None, offset: list | None) -> list[float]:
    """The command's reach for every velocity within ε_b (`slack`) of v and every position within p_b
    (`offset`, adding Σ_b |K_j,b| p_b): each row's largest advance
    under the constant acceleration a over T_w with K_j v raised by Σ_b |K_j,b| ε_b and K_j a by
    Σ_b |K_j,b| η_b (exact for the raised line, which lies above every such motion), plus Σ_b |K_j,b| x_b;
    then the brakes from block speeds |v_b + a_b T_w| + ε_b + η_b T_w + y_b."""
    return _command_rows(backup, _command_plan(backup, v, a, slack, offset), rows, v, a)


def _command_plan(backup: BackupModel, v, a, slack, offset) -> tuple:
    """`_command_head` and the brakes' plan from v + a T_w."""
    head = _command_head(backup, _block_speeds(backup, v), _block_speeds(backup, a), slack, offset)
    ends = _parts(backup, [vj + aj * head[0] for vj, aj in zip(v, a)])
    return _planned(backup, head, ends, [_norm(part) for part in ends])


def _command_head(backup: BackupModel, speeds, accelerations, slack, offset) -> tuple:
    """What `_command_rows` needs besides the rows, v, a and the brakes: (T_w, ε, η, x, the spread of
    the braking speeds), from block speeds |v_b| and the block accelerations |a_b| (or bounds of them:
    every term is nondecreasing in them)."""
    T = backup.hold
    n = len(backup.blocks)
    eps = slack if slack is not None else [0.0] * n
    eta = _spread(backup, speeds, slack)
    dq, dv = _deviation(backup, [s + e for s, e in zip(speeds, eps)],
                        [h + al for h, al in zip(eta, accelerations)], T)
    if offset is not None:
        dq = [x + p for x, p in zip(dq, offset)]
    return T, eps, eta, dq, [e + h * T + y for e, h, y in zip(eps, eta, dv)]


def _command_rows(backup: BackupModel, plan, rows, v, a) -> list[float]:
    T, eps, eta, dq, braking = plan
    n = len(eps)
    reach = []
    for k, _, parts in rows:
        w = _dot(k, v)
        alpha = _dot(k, a)
        held = 0.0
        for b in range(n):
            norm = parts[b][1]
            w += norm * eps[b]
            alpha += norm * eta[b]
            held += _scaled(norm, dq[b])
        reach.append(_hold_advance(w, alpha, T) + held)
    return _apply_braking(backup, braking, rows, reach)


def _braking_plan(backup: BackupModel, blocks, speeds, spread) -> list:
    """Per block, how the brakes advance a row from block velocities `blocks` (speeds `speeds`) each
    known to within `spread`: from speeds |v_b| + spread_b, in any direction where spread_b > 0
    (deflection π) — (path, None) — in the block's cone around v_b where it is 0 — (speed, v_b)."""
    top = [s + e for s, e in zip(speeds, spread)]
    plan = []
    for b, block in enumerate(backup.blocks):
        speed = block.braking_speed(b, top)
        if spread[b] > 0.0 or block.deflection >= math.pi:
            plan.append((_braked_path(block, speed), None))
        else:
            plan.append((speed, blocks[b]))
    return plan


def _apply_braking(backup: BackupModel, plan, rows, reach) -> list[float]:
    """reach + Σ_b the brakes' advance of `_braking_plan`, block by block."""
    for b, (block, (value, direction)) in enumerate(zip(backup.blocks, plan)):
        if direction is None:
            reach = [r + _scaled(parts[b][1], value) for r, (_, _, parts) in zip(reach, rows)]
        else:
            extra = block.advance([parts[b] for _, _, parts in rows], direction, value)
            reach = [r + e for r, e in zip(reach, extra)]
    return reach


def _braked_path(block: BrakeBlock, speed: float) -> float:
    """s_b(speed), inf for an unbounded speed (a hold deviation without a bound)."""
    return block.distance(speed) if speed < math.inf else math.inf


def _scaled(norm: float, length: float) -> float:
    """norm · length, 0 for a row with no part here (even when the length is unbounded)."""
    return norm * length if norm > 0.0 else 0.0


@dataclass(frozen=True)
class Governed:
    """What `govern` decided: the command to send and how far it moved from the one asked for."""

    u: np.ndarray
    share: float          # λ ∈ [0, 1]: 0 = the command as asked, 1 = the fallback
    feasible: bool        # False: not even the fallback is backup-safe (it is sent anyway)


def govern(backup: BackupModel, model, feasible, q: np.ndarray, v: np.ndarray, u: np.ndarray,
           dt: float, slack=None, offset=None, hint: float = 0.0) -> Governed:
    """The backup-safe command closest to u on the segment u → u_g; with `slack` and `offset` (per
    block), a command backup-safe for every velocity within the slack of v and every position within
    the offset of q (an estimate: output feedback, `uncertain_prediction`).

    Most samples are far from every face for their speed: a bound that needs only each polytope's
    smallest slack (`_clearly_safe`) accepts u there without the row-by-row reaches. Elsewhere the
    command's merit m(λ) (`_Probe`: its backup margin less δ; ≥ 0 means backup-safe; only the rows
    near a face for the speed are computed exactly) is found at λ = 0 and, when u fails, at λ = 1;
    when u fails and u_g passes, its root is bracketed by regula falsi with
    the Illinois rule (`_root`): the acceleration is affine in the command, so a(λ) = a_u + λ(a_g − a_u)
    costs no model call; the safe end of the bracket is sent. `hint`: the share the governor found
    the period before (0 or 1: none); the search tries it and its neighbour on the grid first, which
    settles a share that has not moved in two probes (`_root`)."""
    q, v, u = np.asarray(q, float), np.asarray(v, float), np.asarray(u, float)
    q_list, v_list, slack, offset = q.tolist(), v.tolist(), _slack(slack, backup), _slack(offset)
    a_u = model.acceleration(q, v, u).tolist()
    bounds = _block_bounds(backup, v_list, a_u, dt, slack, offset)
    if _clearly_safe(backup, feasible, q_list, bounds) >= backup.margin:
        return Governed(u, 0.0, True)
    probe = _Probe(backup, feasible, q_list, v_list, dt, slack, offset)
    m_u = probe.merit(a_u, bounds)
    if m_u >= 0.0:
        return Governed(u, 0.0, True)
    a_g = backup.fallback_acceleration(v)
    g_list = a_g.tolist()
    m_g = probe.merit(g_list, _block_bounds(backup, v_list, g_list, dt, slack, offset))
    if not m_g >= 0.0:
        # outside the envelope (no stop from here ends δ inside whatever is sent): the one of u and
        # u_g after which the state one period on has the larger backup margin — a law braking at its
        # barrier keeps it above u_g's (that braking is what stops the robot when nothing fails), a law
        # still tracking towards the face does not; u_g never lowers it (§10). But where u_g's own stop
        # (held T_w, then the brakes) ends δ inside and u's does not, u_g: a loss of actuation may follow
        if (_next_margin(backup, feasible, q, v, a_u, dt, slack)
                >= _next_margin(backup, feasible, q, v, a_g, dt, slack)
                and (backup.command_margin(feasible, q, v, a_u, slack) >= backup.margin
                     or not backup.command_margin(feasible, q, v, g_list, slack) >= backup.margin)):
            return Governed(u, 0.0, False)
        return Governed(model.inverse_dynamics(q, v, a_g), 1.0, False)
    share = _root(probe.along(a_u, g_list), m_u, m_g, backup, hint)
    u_g = model.inverse_dynamics(q, v, a_g)
    return Governed(u + share * (u_g - u), share, True)


def command_spans(dt, count: int) -> tuple:
    """How long each of `count` commands was held: one period dt repeated, or dt itself (one span per command)."""
    return (dt,) * count if isinstance(dt, (int, float)) else tuple(dt)


def uncertain_prediction(backup: BackupModel, model, q, v, slack, commands, dt):
    """(q, v, slack, offset) after `commands` (oldest first), each held dt (a period, or one per command:
    shared_controller.in_flight's spans), from a state whose velocity
    is known to within `slack` per block (the observer's v̂ and `BackupModel.observer_error`): q and v
    are stepped as shared_controller.predict steps them (the model's acceleration at the period's
    start, held), and per period the slack grows by the acceleration's spread and the hold's deviation,
    ε ← ε + η dt + y, the offset — how far q may be from the prediction — by p ← p + ε dt + ½η dt² + x
    (η = acceleration_spread at the period's largest speeds, (x, y) the deviation over dt from speeds
    |v_b| + ε_b and accelerations |a_b| + η_b). What it leaves out is what `predict` leaves out: the
    plant's friction and its parameters against the model's.

    It runs once per control period over every period of the loop delay, so the per-period work is
    kept to the arithmetic: the block axes and the hold deviation's methods are looked up once, and
    the check that the slack stays within its bound is the period's own growth (`_growth`)."""
    q, v = np.asarray(q, float), np.asarray(v, float)
    eps = [float(e) for e in slack]
    offset = [0.0] * len(backup.blocks)
    spans = command_spans(dt, len(commands))
    axes = [tuple(block.axes) for block in backup.blocks]
    spread = getattr(backup.hold_deviation, "acceleration_spread", None)
    by_block = getattr(backup.hold_deviation, "by_block", None)
    deviation = by_block if by_block is not None else functools.partial(_deviation, backup)
    for u, dt in zip(commands, spans):
        a = model.acceleration(q, v, u)
        v_list, a_list = v.tolist(), a.tolist()
        speeds = [_norm([v_list[i] for i in axis]) for axis in axes]
        accelerations = [_norm([a_list[i] for i in axis]) for axis in axes]
        grown = _growth(spread, deviation, speeds, accelerations, eps, dt)
        # a bound the slack cannot leave over the period: one that `grown` maps below itself (everything is
        # nondecreasing in it, so the slack, starting below it, stays below)
        bound = [e + 2.0 * (g - e) for e, g in zip(eps, grown(grown(eps)[0])[0])]
        end, eta, dq = grown(bound)
        while any(g > b for g, b in zip(end, bound)):
            bound = [e + 2.0 * (b - e) + 1e-12 for e, b in zip(eps, bound)]
            end, eta, dq = grown(bound)
        offset = [p + e * dt + 0.5 * h * dt * dt + x for p, e, h, x in zip(offset, eps, eta, dq)]
        eps = end
        q = q + dt * v + (0.5 * dt * dt) * a
        v = v + dt * a
    return q, v, eps, offset


def _growth(spread, deviation, speeds: list, accelerations: list, eps: list, dt: float):
    """One period of `uncertain_prediction` from block speeds, accelerations and slack ε at its start: the
    function of a bound on the slack over the period that gives (the slack at its end, the acceleration's
    spread η at the bound, the deviation x). `spread`: the hold deviation's acceleration_spread, or None;
    `deviation(speeds, accelerations, T)`: its by_block, or `_deviation`."""
    fastest = [s + al * dt for s, al in zip(speeds, accelerations)]
    base = [s + e for s, e in zip(speeds, eps)]
    zeros = [0.0] * len(speeds)

    def grown(bound: list):
        eta = zeros if spread is None else spread(fastest, bound)
        dq, dv = deviation(base, [al + h for al, h in zip(accelerations, eta)], dt)
        return [e + h * dt + y for e, h, y in zip(eps, eta, dv)], eta, dq

    return grown


def _next_margin(backup: BackupModel, feasible, q: np.ndarray, v: np.ndarray, a, dt: float, slack=None) -> float:
    """The backup margin of the state one period on under the acceleration a (with `slack`, of every
    velocity that close to it)."""
    a = np.asarray(a, float)
    return backup.state_margin(feasible, q + v * dt + 0.5 * a * dt * dt, v + a * dt, slack)


def _root(merit, m_lo: float, m_hi: float, backup: BackupModel, hint: float = 0.0) -> float:
    """The least λ ∈ (0, 1] with merit(λ) ≥ 0, from above: regula falsi on the bracket [lo, hi]
    (merit(lo) < 0 ≤ merit(hi)) with the Illinois rule (the end kept twice has its merit halved
    for the next chord), at most `backup.iterations` probes, until hi − lo ≤ 2⁻¹²; a bracket the
    chords leave wider (they creep from one end where the merit turns flat) is bisected until it is
    2⁻¹² (at most 12 more probes). A chord point that is not strictly inside the bracket (a merit of
    −inf: no polytope contains the state) is replaced by the midpoint, and every probe is rounded to
    the grid (`_on_grid`). Returns hi: it always passes, and on a nondecreasing merit it is the least
    grid point that passes. On the bench's adversarial-wall replay the chords take 9.7 probes on
    average where bisection takes 12 (5.3 told the last period's λ). The batched governor
    (sharedctl/batched/backup.py, compiled_backup.py) runs the same arithmetic per robot.

    With a `hint` in (0, 1) (the last period's λ) the bracket is first narrowed by two probes: the
    hint on the grid, then its neighbour towards the other end (below it when it passes, above when
    it fails), both counted in the `backup.iterations` probes. A λ that has not moved since the last
    period is then settled; one that moved starts the chords from a bracket one of whose ends is a
    grid step from the hint (docs/control.md §10, the warm start: every end is still a probe's
    verdict, so what is sent still passes)."""
    lo, hi, f_lo, f_hi, kept, probes = 0.0, 1.0, m_lo, m_hi, 0, backup.iterations
    if 0.0 < hint < 1.0:
        lam = _on_grid(hint, lo, hi)
        m = merit(lam)
        probes -= 1
        lo, f_lo, hi, f_hi = (lo, f_lo, lam, m) if m >= 0.0 else (lam, m, hi, f_hi)
        if hi - lo > _LAMBDA_RESOLUTION:
            lam = hi - _LAMBDA_RESOLUTION if m >= 0.0 else lo + _LAMBDA_RESOLUTION
            m = merit(lam)
            probes -= 1
            lo, f_lo, hi, f_hi = (lo, f_lo, lam, m) if m >= 0.0 else (lam, m, hi, f_hi)
    for _ in range(probes):
        if hi - lo <= _LAMBDA_RESOLUTION:
            break
        lam = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not lo < lam < hi:
            lam = 0.5 * (lo + hi)
        lam = _on_grid(lam, lo, hi)
        m = merit(lam)
        if m >= 0.0:
            hi, f_hi = lam, m
            f_lo = 0.5 * f_lo if kept < 0 else f_lo
            kept = -1                     # lo kept
        else:
            lo, f_lo = lam, m
            f_hi = 0.5 * f_hi if kept > 0 else f_hi
            kept = 1                      # hi kept
    while hi - lo > _LAMBDA_RESOLUTION:   # the chords stalled (a merit that turns flat): bisect what is left
        lam = _on_grid(0.5 * (lo + hi), lo, hi)
        if merit(lam) >= 0.0:
            hi = lam
        else:
            lo = lam
    return hi


def _on_grid(lam: float, lo: float, hi: float) -> float:
    """λ rounded to the nearest multiple of the resolution strictly inside [lo, hi] (both on the grid,
    at least two steps apart). A probe on the grid decides the same in every implementation of the
    search: a chord point that differs in its last bits moves it only when it falls within rounding
    of a half step, and a merit at a grid point is within rounding of 0 only when the root is."""
    r = _LAMBDA_RESOLUTION
    return min(max(round(lam / r) * r, lo + r), hi - r)


class _Probe:
    """One sample's (q, v) for `govern`: the merit of an acceleration a held from it,
    m(a) = min(command margin, the next state's backup margin) − δ.

    Row by row, a row whose crude bound x_j + Σ_b |K_j,b| C_b (`_block_bounds`: it bounds both the
    command's and the next state's advance) is at or below −δ cannot decide the sign: its value is
    taken as that bound, −(x_j + Σ_b |K_j,b| C_b) ≥ δ, and its exact reach is not computed; the
    rows near a face are computed exactly. The merit's sign is exact; its value, where it is ≥ 0,
    may be a lower row's bound. When the command margin fails (< δ), the merit is that margin
    less δ: its sign is all the governor decides on.

    `along(a_u, a_g)` gives the root search its merit(λ) on the segment a(λ) = a_u + λ(a_g − a_u).
    With a hold deviation or a slack, the crude bounds that sort the rows are computed once, at the
    largest block norms |a_b| on the segment (each is convex in λ, so it is the larger of its values at
    the two ends): a larger bound only computes more rows exactly, so each probe's sign is its exact
    merit's. Everything that decides the sign — the hold's deviation terms, the next state's slack and
    its stop — is computed at a(λ) itself. (Bounded at the segment's largest norms too, those terms
    would fail every blend of a command whose own deviation is large: the yaw's grows with |a_ψ|, and
    a holding machine's law asking for (−302, 370, 342) N, N·m far from its reference would have the
    fallback sent at every sample while the robot stands still, docs/control.md §10.)"""

    __slots__ = ("backup", "regions", "q", "v", "dt", "slack", "offset", "uncertain", "speeds", "eps", "eta")

    def __init__(self, backup: BackupModel, feasible, q: list, v: list, dt: float, slack: list | None = None,
                 offset: list | None = None):
        self.backup, self.q, self.v, self.dt, self.slack, self.offset = backup, q, v, dt, slack, offset
        self.regions = [(rows, [_dot(k, q) + t for k, t, _ in rows]) for rows in _region_rows(backup, feasible)]
        self.uncertain = backup.hold_deviation is not None or slack is not None or offset is not None
        if self.uncertain:
            self.speeds = _block_speeds(backup, v)
            self.eps = slack if slack is not None else [0.0] * len(backup.blocks)
            self.eta = _spread(backup, self.speeds, slack)

    def merit(self, a: list, bounds: list) -> float:
        return self._merit(a, self._split(bounds))

    def along(self, a_u: list, a_g: list):
        """merit(λ) of a(λ) = a_u + λ(a_g − a_u) (see the class)."""
        step = [g - h for g, h in zip(a_g, a_u)]

        def at(lam: float) -> list:
            return [h + lam * d for h, d in zip(a_u, step)]

        if not self.uncertain:
            backup, v, dt = self.backup, self.v, self.dt
            return lambda lam: self.merit(at(lam), _block_bounds(backup, v, at(lam), dt))
        backup = self.backup
        held = [max(x, y) for x, y in zip(_block_speeds(backup, a_u), _block_speeds(backup, a_g))]
        split = self._split(_uncertain_bounds_at(backup, self.speeds, held, self.dt, self.slack, self.offset))
        return lambda lam: self._merit(at(lam), split)

    def _split(self, bounds: list) -> list:
        """Per polytope (rows, row values, the near rows, their subset, far): `far` the least bound of
        the rows that cannot decide."""
        delta = self.backup.margin
        crude_of = _crude_rows(bounds)
        split = []
        for rows, x in self.regions:
            near, far = [], math.inf
            for j, (xj, cj) in enumerate(zip(x, crude_of(rows))):
                if xj + cj > -delta:
                    near.append(j)
                else:
                    far = min(far, -(xj + cj))
            split.append((rows, x, near, [rows[j] for j in near], far))
        return split

    def _merit(self, a: list, split: list) -> float:
        backup, q, v, dt, slack, offset = self.backup, self.q, self.v, self.dt, self.slack, self.offset
        delta = backup.margin
        command = -math.inf
        plan = None                       # the command's reach plan, made once for every polytope
        for _, x, near, subset, far in split:
            if max(x) < 0.0:
                value = far
                if near:
                    if self.uncertain:
                        if plan is None:
                            plan = _command_plan(backup, v, a, slack, offset)
                        reach = _command_rows(backup, plan, subset, v, a)
                    else:
                        reach = _command_reach(backup, subset, v, a)
                    value = min(value, min(-(x[j] + r) for j, r in zip(near, reach)))
                command = max(command, value)
        if command < delta:
            return command - delta
        q1 = [qi + vi * dt + 0.5 * ai * dt * dt for qi, vi, ai in zip(q, v, a)]
        v1 = [vi + ai * dt for vi, ai in zip(v, a)]
        if self.uncertain:
            return min(command, self._uncertain_state(split, q1, v1, a)) - delta
        state = -math.inf
        for rows, _, near, subset, far in split:
            x1 = [_dot(rows[j][0], q1) + rows[j][1] for j in near]
            if x1 and max(x1) >= 0.0:
                continue
            value = far
            if near:
                reach = _state_reach(backup, subset, v1)
                value = min(value, min(-(xj + r) for xj, r in zip(x1, reach)))
            state = max(state, value)
        return min(command, state) - delta

    def _next_uncertainty(self, held: list) -> tuple[list, list]:
        """(how far the next position may be from q1, per block; the next velocity's slack) for block
        accelerations at most `held` (see `_uncertain_state`)."""
        backup, dt, eps, eta = self.backup, self.dt, self.eps, self.eta
        dq, dv = _deviation(backup, [s + e for s, e in zip(self.speeds, eps)],
                            [h + al for h, al in zip(eta, held)], dt)
        moved = [e * dt + 0.5 * h * dt * dt + x for e, h, x in zip(eps, eta, dq)]
        if self.offset is not None:
            moved = [m + p for m, p in zip(moved, self.offset)]
        return moved, [e + h * dt + y for e, h, y in zip(eps, eta, dv)]

    def _uncertain_state(self, split, q1, v1, a) -> float:
        """The next state's backup margin when the period departs from constant acceleration by
        (x_b, y_b) = the hold deviation over dt, and the position is known to within p_b (`offset`),
        the velocity to within ε_b (`slack`), the acceleration to within η_b: every row value
        x_j ≤ K_j q1 + T_j + Σ_b |K_j,b| (p_b + ε_b dt + ½η_b dt² + x_b) and every velocity within
        ε_b + η_b dt + y_b of v1. A polytope counts only when it contains every such position. The
        next sample computes its fallback at its own velocity under state feedback (no spread for
        it), at its estimate under output feedback."""
        backup = self.backup
        n = len(backup.blocks)
        moved, slack1 = self._next_uncertainty(_block_speeds(backup, a))
        blocks = _parts(backup, v1)
        plan = None
        state = -math.inf
        for rows, _, near, subset, far in split:
            x1 = []
            for j in near:
                k, t, parts = rows[j]
                value = _dot(k, q1) + t
                for b in range(n):
                    value += _scaled(parts[b][1], moved[b])
                x1.append(value)
            if x1 and max(x1) >= 0.0:
                continue
            value = far
            if near:
                if plan is None:
                    speeds = [_norm(part) for part in blocks]
                    head = _state_head(backup, speeds, slack1, None, self.slack is not None)
                    plan = _planned(backup, head, blocks, speeds)
                reach = _state_rows(backup, plan, subset, blocks)
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


def _block_bounds(backup: BackupModel, v: list, a: list, dt: float, slack: list | None = None,
                  offset: list | None = None) -> list[float]:
    """Per block, C_b = t_b(T + dt) + s_b(S_b(t)), t_b = |v_b| + |a_b| T, T = max(T_w, dt), S_b the
    block's braking speed from the t's: no row advances more than Σ_b |K_j,b| C_b, neither while a is
    held T_w then braked, nor over one period plus the stop of the state it leads to
    (docs/control.md §10). Floats in, floats out. With a hold deviation, a slack or an offset,
    `_uncertain_block_bounds`."""
    if backup.hold_deviation is not None or slack is not None or offset is not None:
        return _uncertain_block_bounds(backup, v, a, dt, slack, offset)
    T = max(backup.hold, dt)
    tops = [_norm([v[i] for i in block.axes]) + _norm([a[i] for i in block.axes]) * T for block in backup.blocks]
    return [top * (T + dt) + block.distance(block.braking_speed(b, tops))
            for b, (block, top) in enumerate(zip(backup.blocks, tops))]


def _uncertain_block_bounds(backup: BackupModel, v: list, a: list, dt: float, slack: list | None,
                            offset: list | None) -> list[float]:
    """`_block_bounds` with a hold deviation and a slack ε_b: with η the acceleration's spread at |v_b|,
    (x, y) the deviation over T from speeds |v_b| + ε_b and accelerations |a_b| + η_b, the speeds
    t_b = |v_b| + ε_b + (|a_b| + η_b)T + y_b bound every speed the command's hold and the next state reach;
    with η̄ the spread at speeds and slacks t (the next state's, at most) and (x_g, y_g) the deviation of
    the fallback held T_w from speeds t at its deceleration there plus η̄,

        C_b = t_b(T + dt) + x_b + ½η̄_b T² + x_g,b + s_b(S_b(t + η̄T + y_g)),

    which covers both as before (‖K_j‖ ≤ Σ_b |K_j,b| where one deviation moves every coordinate,
    `_rows_of`); an offset p_b adds p_b to C_b."""
    return _uncertain_bounds_at(backup, _block_speeds(backup, v), _block_speeds(backup, a), dt, slack, offset)


def _uncertain_bounds_at(backup: BackupModel, speeds: list, held: list, dt: float, slack: list | None,
                         offset: list | None) -> list[float]:
    """`_uncertain_block_bounds` from block speeds |v_b| and bounds `held` of the block accelerations
    |a_b| (nondecreasing in them)."""
    T = max(backup.hold, dt)
    n = len(backup.blocks)
    eps = slack if slack is not None else [0.0] * n
    eta = _spread(backup, speeds, slack)
    accelerations = [h + al for h, al in zip(eta, held)]
    dq, dv = _deviation(backup, [s + e for s, e in zip(speeds, eps)], accelerations, T)
    tops = [s + e + al * T + y for s, e, al, y in zip(speeds, eps, accelerations, dv)]
    eta_top = _spread(backup, tops, None if slack is None else tops)
    falls = [d + h for d, h in zip(_fallback_decelerations(backup, tops), eta_top)]
    dq_g, dv_g = _deviation(backup, tops, falls, backup.hold)
    ends = [t + h * T + y for t, h, y in zip(tops, eta_top, dv_g)]
    if offset is not None:
        dq = [x + p for x, p in zip(dq, offset)]
    return [top * (T + dt) + x + 0.5 * h * T * T + x_g + _braked_path(block, block.braking_speed(b, ends))
            for b, (block, top, x, h, x_g) in enumerate(zip(backup.blocks, tops, dq, eta_top, dq_g))]


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
                     a=None, slack=None, offset=None) -> tuple[list, list]:
    """Definition 2's rows seen through the stop: inside a polytope, each row value x_j is moved
    towards its face by the state's reach (kept just inside, so that containment is unchanged);
    rates and rows already outside are left as they are. Classifying these makes a state
    hazardous when its distance to a face, less the travel while the loss of actuation is
    detected and the braking distance at the current speed, falls below the bands. With `a`,
    the acceleration of the operator's command, the reach is that of holding it (command_reach):
    the state is hazardous when the operator's own command would not be backup-safe, so the
    machine holds authority wherever the governor would have to change u_h. With `slack` (per
    block), the reach of every velocity that close to v, and with `offset`, of every position that
    close to the rows' q (an estimate: output feedback).

    A row that stays at or below −`far` even moved by its crude bound Σ_b |K_j,b| C_b
    (`_block_bounds`, dt = 0) is returned unmoved: `far` is the widest band, b2, and Definition 2,
    the standoff test and the hand-back test classify a row there alike whether or not it is
    moved, so only the rows near a face pay for the exact reach."""
    values, rates = rows
    v_list = v.tolist() if isinstance(v, np.ndarray) else [float(e) for e in v]
    a_list = [0.0] * len(v_list) if a is None else _as_floats(a)
    slack, offset = _slack(slack, backup), _slack(offset)
    stacked = _stacked_rows(backup, feasible)
    crude = _crude_rows(_block_bounds(backup, v_list, a_list, 0.0, slack, offset))(stacked)
    near = [j for j, (x, c) in enumerate(zip(values, crude)) if x < 0.0 and x + c > -far]
    if not near:
        return rows
    subset = [stacked[j] for j in near]
    reach = (_state_reach(backup, subset, v_list, slack, offset) if a is None
             else _command_reach(backup, subset, v_list, a_list, slack, offset))
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


#: A real brake holds at rest; the simulated one is c_b tanh(ω/ω_b) (ω_b = 0.2 rad/s), which fades
#: below a wheel speed of a few ω_b, i.e. below about 1 cm/s: the last stretch of a stop is
#: slower than a_c allows. 0.5 mm covers it (tests/test_backup.py measures the plant's stops).
CREEP = 5e-4


#: The output-feedback envelope of the robot, per block (m/s, rad/s): an assumption, not a bound — the
#: observer's measured errors exceed it, and a translation slack that covers them moves the take-over
#: ahead of the operator's wish (docs/control.md §10, "Output feedback: the observer's error")
OBSERVER_ERROR = (0.0, 0.5)


def omni_backup(parameters, brake_torque: float, friction_coulomb: float, friction_viscous: float,
                hold: float, margin: float = 0.01) -> BackupModel:
    """The omnidirectional robot's stop (docs/control.md §10, "The robot's stop";
    models/omni_robot_stop.py): per wheel a Coulomb torque c = friction_coulomb + brake_torque and a
    viscous b, shared by the translation and the yaw. Translation: a_t = 1.5c/(r m1); yaw:
    a_ψ = 3cL/(r m3); both k = κ = min(3b/(2r²m1), 3bL²/(r²m3)), braking from their energy speeds
    S_t² = |v|² + (m3/m1)ψ̇², S_ψ² = ψ̇² + (m1/m3)|v|², in any direction (deflection π). The held
    wheel torques' force turns with the robot: `OmniHoldDeviation`."""
    bounds = OmniStopBounds.of(parameters.theta(), parameters.wheel_radius, parameters.wheel_distance,
                               friction_coulomb + brake_torque, friction_viscous)
    for_translation, for_yaw = energy_weights(bounds)
    translation = BrakeBlock((0, 1), bounds.translation_deceleration, bounds.viscous, math.pi, CREEP,
                             for_translation)
    yaw = BrakeBlock((2,), bounds.yaw_deceleration, bounds.viscous, math.pi, CREEP / parameters.wheel_distance,
                     for_yaw)
    return BackupModel(hold, (translation, yaw), margin, hold_deviation=bounds.hold_deviation(),
                       observer_error=OBSERVER_ERROR)


def arm_backup(parameters, brake_torque, hold: float, margin: float = 0.01) -> BackupModel:
    """The two-link arm's stop (docs/control.md §10, "The arm's stop"): one block over both joints
    with a_c from the joint brakes' Coulomb torques `brake_torque` = (c1, c2) (N·m, each above its
    joint's largest gravity torque), k = 0 and deflection π; the hold's deviation from constant
    acceleration bounded per probe from ‖v‖, ‖a‖ and T (models/planar_arm_stop.py)."""
    bounds = ArmBounds.of(parameters.theta())
    block = BrakeBlock((0, 1), bounds.braking_deceleration(brake_torque), 0.0)
    return BackupModel(hold, (block,), margin, hold_deviation=ArmHoldDeviation.of(bounds))
