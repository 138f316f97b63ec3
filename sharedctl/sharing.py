"""Authority sharing between the operator and the machine (paper (46)–(47)).

The paper's sharing function k_s^i is a Schmitt trigger on the sets of Definition 2:
0 (machine) in the hazardous set, its last value in the hysteresis set, 1 (human) in the safe
set. The printed blend lost its signs and, read literally, neither gives transparency nor a
smooth hand-over (docs/control.md §6). The reading implemented here:

* **transparency** — in the safe set, after the minimum dwell, u_s = u_h exactly (k_s = 1);
* **full machine authority** in the hazardous set — u_s = u_f (k_s = 0, k_f = 1);
* **release when the push turns away** — the machine hands authority back as soon as the state is
  safe, *or* the state is not hazardous and the operator's push has turned away (the wish q_d is
  inside Q_a by at least ε and the force u_h pushes towards no face the robot is within b_s of),
  after the minimum dwell Δt in both cases, and in neither while u_h still pushes at a face
  hazardous since the take-over (`held_rows`; `_pushes_at`): released into that push, the operator
  would drive the state straight back into the hazardous set. While the push lasts, the machine
  keeps authority and, running its law on the projected reference, brings the robot to rest ε
  inside the face — in the standoff band of sets.py, which is not
  safe — so an operator pushing out of the set meets one take-over and one release, not a
  pulse train;
* **the blend** — where k_s = 0 outside the hazardous set, u_s = k_h u_h + k_f u_f, k_f = 1 − k_h,
  with k_h relaxing (time constant τ) towards 1 once the push has turned away and towards 0 while
  it has not, and k_h = 0 in the hazardous set. k_h is continuous along every trajectory that
  stays latched, so u_s has no jump there; authority is MACHINE whenever k_h = 0 (u_s = u_f).

Minimum dwell. Near a face both allowance curves of Definition 2 go to zero, so the
hysteresis band between them is thin: the machine's first push reverses the approach and
puts the state straight back in the safe set. The machine therefore keeps authority for at
least Δt = min_machine_dwell after taking over (Theorem 5 assumes such a Δt > 0).

Group selection: on taking over, the machine picks, among the groups of the polytopes
that contain q, the one of least Lyapunov value that contains every hazardous row of its
polytope (so the law it runs sees every face it is being pushed into). It keeps that group
until the group stops applying (q left its polytope) or stops covering the hazardous rows.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .constraints import FeasibleSet
from .sets import Bands, SetClass, Situation, classify


class Authority(enum.IntEnum):
    HUMAN = 0     # k_s = 1: u_s = u_h
    SHARED = 1    # k_s = 0 outside the hazardous set, 0 < k_h: u_s = k_h u_h + k_f u_f
    MACHINE = 2   # k_s = 0 and k_h = 0 (always in the hazardous set, or machine-only mode): u_s = u_f


class Mode(enum.Enum):
    SHARED = "shared"     # the paper's shared controller
    MACHINE = "machine"   # no operator: the machine laws alone (Theorems 1–4)
    HUMAN = "human"       # no machine: the operator alone (a baseline)


class LawRole(enum.IntEnum):
    TRACKING = 0   # the configured law (ce: (12); nce: (12) with the composite update; of: (25))
    HAZARD = 1     # the law that runs in the hazardous set (the configured one; of: its barrier form, §4.3)


@dataclass(frozen=True)
class SharingParameters:
    bands: Bands = Bands()
    blend_time_constant: float = 0.3      # τ (s) of k_h in the shared hysteresis state
    mode: Mode = Mode.SHARED
    min_machine_dwell: float = 0.25       # Δt (s): shortest machine intervention (Theorem 5's Δt > 0)
    #: keep authority while the operator pushes at a face hazardous since the take-over (docs/control.md §6);
    #: False: release in the safe set whatever the push (Theorem 5's claim 3 read literally)
    hold_pushed_faces: bool = True

    def __post_init__(self):
        if self.blend_time_constant <= 0 or self.min_machine_dwell < 0:
            raise ValueError("blend_time_constant must be > 0 and min_machine_dwell >= 0")


@dataclass(frozen=True)
class ArbiterState:
    """The arbiter's memory: k_s (as `machine_latched`), the active group, the law role, k_h."""

    machine_latched: bool = False
    group: int | None = None
    role: LawRole = LawRole.TRACKING
    k_h: float = 1.0
    machine_time: float = 0.0  # seconds since the machine last took over
    switches: int = 0          # authority changes so far
    group_switches: int = 0
    held_rows: tuple[int, ...] = ()   # the rows hazardous since the machine took over (FeasibleSet.row_ids)


class Decision(NamedTuple):
    """What to apply until the next sample (a named tuple: one is built every sample)."""

    authority: Authority
    group: int | None
    role: LawRole
    k_h: float
    k_f: float
    situation: Situation
    group_changed: bool
    role_changed: bool


def covering(feasible: FeasibleSet, situation: Situation, group: int) -> bool:
    """Does `group` contain every hazardous row of its polytope?"""
    grp = feasible.groups[group]
    rows = situation.hazard_rows.get(grp.region)
    if rows is None:
        return False
    return set(rows) <= set(grp.rows)


def _clear_of_faces(feasible: FeasibleSet, group: int | None, q: np.ndarray, bands: Bands, rows=None) -> bool:
    """Every row of the group at least b1 inside its face (x_j ≤ −b1). `rows`: row_values(q, ·), if known."""
    if group is None:
        return True
    b1 = bands.b1
    x = feasible.groups[group].values(q).tolist() if rows is None else feasible.group_rows(group, rows)[0]
    return all(xj <= -b1 for xj in x)


def select_group(feasible: FeasibleSet, situation: Situation, lyapunov, reference=None) -> int | None:
    """Least-Lyapunov group among those that apply and cover their polytope's hazardous rows.

    `lyapunov(g)` gives the selection value of group g. If no group covers every hazardous
    row (a corridor narrower than the bands), the one covering most rows wins. With
    `reference` (per group: is its projected reference q_r inside its whole polytope?), groups
    whose q_r is inside are preferred: a group's projection only respects its own n rows, and
    the machine should not be led towards a face its group does not contain.
    """
    best, best_key = None, None
    for g, grp in enumerate(feasible.groups):
        if grp.region not in situation.region_class:
            continue
        rows = situation.hazard_rows[grp.region]
        missed = len(set(rows) - feasible.group_row_sets[g]) if rows else 0
        value = lyapunov(g)
        if not math.isfinite(value):
            continue
        outside = 0 if reference is None else int(not reference[g])
        key = (missed, outside, value)
        if best_key is None or key < best_key:
            best, best_key = g, key
    return best


def arbitrate(
    feasible: FeasibleSet,
    params: SharingParameters,
    state: ArbiterState,
    q: np.ndarray,
    v: np.ndarray,
    intent: float,
    dt: float,
    lyapunov,
    reference: np.ndarray | None = None,
    rows: tuple[list, list] | None = None,
    push_away: bool = False,
    pushes: list | None = None,
    push_power: float = 0.0,
) -> tuple[ArbiterState, Decision]:
    """One sample of the sharing function: classify, latch, select, blend.

    `v` is the measured velocity (state feedback, (46)) or the observer's v̂ (output
    feedback, (47)). `intent` is v_h of (45). `lyapunov(g)` is evaluated lazily; `reference`
    holds every group's projected reference (see select_group). `rows`: the caller's
    `feasible.row_values(q, v)`, if it has them already. `push_away`: has the operator's push turned
    away from the faces (push_turned_away)? False (unknown) releases in the safe set only. `pushes`:
    k_j u_h of every row, stacked as in `feasible.row_values` (None: unknown, no row is pushed), and
    `push_power`: v·u_h. The machine keeps authority while u_h pushes at a face hazardous since it took
    over (`held_rows`), in every polytope that contains q, safe state or not (`_pushes_at`): released
    into such a push, the operator would drive the state back into the hazardous set (docs/control.md
    §6).
    """
    situation = classify(feasible, q, v, params.bands, rows)
    overall = situation.overall
    mode = params.mode

    if mode is Mode.HUMAN:
        return state, Decision(Authority.HUMAN, None, LawRole.TRACKING, 1.0, 0.0, situation, False, False)

    # --- k_s: the Schmitt trigger -------------------------------------------
    latched = state.machine_latched
    pushing = bool(pushes is not None and state.held_rows and params.hold_pushed_faces and _pushes_at(
        feasible, state.held_rows, situation.containing, pushes, feasible.row_values(q, v)[0], push_power,
        params.bands.b2))
    machine_time = state.machine_time + dt if latched else 0.0
    if mode is Mode.MACHINE:
        latched = True
    elif overall is SetClass.HAZARD:
        if not latched:
            machine_time = 0.0
        latched = True
    elif (overall is not SetClass.HAZARD and machine_time >= params.min_machine_dwell
          and (overall is SetClass.SAFE or push_away) and not pushing):
        latched = False
    switches = state.switches + (latched != state.machine_latched and mode is Mode.SHARED)

    # --- law role (which law the machine runs) -------------------------------
    role = state.role
    if overall is SetClass.HAZARD:
        role = LawRole.HAZARD
    elif (role is LawRole.HAZARD and overall is SetClass.SAFE
          and _clear_of_faces(feasible, state.group, q, params.bands, rows)):
        role = LawRole.TRACKING
    # otherwise hold the role: the hazard law keeps running until the state is safe *and*
    # outside the inner band of its group (a law-level Schmitt trigger). It matters where the two
    # roles run different laws (of: (25) tracks, (12) on v̂ in the hazardous set, docs/control.md
    # §4.3): the tracking law resumes only where it is well-conditioned.

    # --- group ------------------------------------------------------------------
    group = state.group
    taking_over = latched and not state.machine_latched
    needs_group = latched or mode is Mode.MACHINE
    if needs_group:
        stale = (
            group is None
            or taking_over
            or feasible.groups[group].region not in situation.region_class
            or not covering(feasible, situation, group)
            and situation.hazard_rows.get(feasible.groups[group].region)
        )
        if stale:
            chosen = select_group(feasible, situation, lyapunov, reference)
            if chosen is not None:
                group = chosen
    group_changed = group != state.group

    # --- weights ----------------------------------------------------------------
    if not latched:
        authority, k_h = Authority.HUMAN, 1.0
    elif mode is Mode.MACHINE or overall is SetClass.HAZARD:
        authority, k_h = Authority.MACHINE, 0.0
    else:
        # latched outside the hazardous set: k_h relaxes towards 1 once the push has turned away, towards
        # 0 (where it stays exactly, from the hazardous set's 0) while it has not
        target = 1.0 if push_away and not pushing else 0.0
        k_h = state.k_h + (target - state.k_h) * (1.0 - math.exp(-dt / params.blend_time_constant))
        authority = Authority.MACHINE if k_h == 0.0 else Authority.SHARED
    k_f = 1.0 - k_h

    held_rows = ()
    if latched and mode is Mode.SHARED:
        held_rows = state.held_rows if state.machine_latched else ()
        if overall is SetClass.HAZARD:
            held_rows = _with_hazard_rows(feasible, held_rows, situation)
    new_state = ArbiterState(      # every field (as dataclasses.replace would, without its overhead)
        machine_latched=latched,
        group=group,
        role=role,
        k_h=k_h,
        machine_time=machine_time if latched else 0.0,
        switches=int(switches),
        group_switches=state.group_switches + int(group_changed and state.group is not None),
        held_rows=held_rows,
    )
    decision = Decision(authority, group, role, k_h, k_f, situation, group_changed, role != state.role)
    return new_state, decision


def _pushes_at(feasible: FeasibleSet, held_rows: tuple[int, ...], containing: tuple[int, ...], pushes, values,
               power: float, far: float) -> bool:
    """Does u_h push at one of `held_rows` in every polytope containing q? A row is pushed when u_h heads
    at it (k_j u_h > 0); a row farther than `far` (b2) from its face, hazardous only through the reach of
    the stop, also when u_h adds kinetic energy (`power` = v·u_h > 0: every reach grows with it).
    (As for push_turned_away, a union asks for one polytope: a push at a held face of one polytope
    that lies inside another is not a push out of Q_a.)"""
    if not containing:
        return False
    ids, spans = feasible.row_ids, feasible.row_spans
    energy = power > 0.0
    for region in containing:
        first, end = spans[region]
        if not any(ids[j] in held_rows and (pushes[j] > 0.0 or energy and values[j] <= -far)
                   for j in range(first, end)):
            return False
    return True


def _with_hazard_rows(feasible: FeasibleSet, held_rows: tuple[int, ...], situation: Situation) -> tuple[int, ...]:
    """`held_rows` and the situation's hazardous rows, as distinct row ids (FeasibleSet.row_ids), sorted."""
    ids, spans = feasible.row_ids, feasible.row_spans
    rows = set(held_rows)
    for region, local in situation.hazard_rows.items():
        first = spans[region][0]
        rows.update(ids[first + j] for j in local)
    return tuple(sorted(rows))


def wish_admissible(feasible: FeasibleSet, q_d, epsilon: float) -> bool:
    """Is the operator's wish q_d inside Q_a by at least ε (inside some polytope, every row ≤ −ε)?
    Where it is, the projection (7) leaves it (nearly) unchanged: the operator asks for nothing the
    machine would refuse."""
    return feasible.margin(np.asarray(q_d, dtype=float)) >= epsilon


def push_turned_away(feasible: FeasibleSet, q, q_d, u_h, epsilon: float, bands: Bands, values=None,
                     pushes=None) -> bool:
    """Has the operator's push turned away from the faces? The wish is admissible (wish_admissible) and,
    in some polytope that contains q, u_h has no component towards a face the robot is within the
    standoff band of (k_j u_h ≤ 0 for every row with −b_s < k_j q + t_j < 0): both the wish and the
    hand say "back in". (As for the sets, a union asks for one polytope: pushing at a face of one
    polytope that lies inside another is not pushing out of Q_a.) `values`: the row values to judge
    "within the standoff band" by, if not K q + T — the rows seen through the fail-safe stop
    (backup.speed_aware_rows), so that a push still counts while its stop would end in the band. `pushes`:
    k_j u_h of every row, if known (`operator_pushes`)."""
    if not wish_admissible(feasible, q_d, epsilon):
        return False
    standoff = bands.standoff
    if values is None or pushes is None:
        own_values, own_pushes = feasible.row_values(q, u_h)
        values = own_values if values is None else values
        pushes = own_pushes if pushes is None else pushes
    for first, end in feasible.row_spans:
        x = values[first:end]
        if all(xj < 0.0 for xj in x) and not any(
                -standoff < xj and push > 0.0 for xj, push in zip(x, pushes[first:end])):
            return True
    return False


def operator_pushes(feasible: FeasibleSet, u_h) -> list:
    """k_j u_h of every row, stacked as in `feasible.row_values`: how hard the operator pushes at each face."""
    return feasible.row_rates(u_h)


def shared_input(decision: Decision, u_h: np.ndarray, u_f: np.ndarray) -> np.ndarray:
    """u_s of (46)/(47) under a decision: u_h (k_s = 1), u_f (hazardous), or k_h u_h + k_f u_f."""
    if decision.authority is Authority.HUMAN:
        return u_h
    if decision.authority is Authority.MACHINE:
        return u_f
    return decision.k_h * u_h + decision.k_f * u_f
