"""sharing.arbitrate for a whole batch: the Schmitt trigger k_s with its minimum machine dwell,
the law-level trigger, group selection and the blend k_h of (46)/(47) (docs/control.md §6).

The arbiter's memory is one array per field of sharing.ArbiterState; a group of −1 stands for
None. Each rule below is the scalar rule written over the batch, in the same order.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..sharing import Authority, LawRole, Mode, SharingParameters
from .geometry import HAZARD, SAFE, GroupTable, Situation, group_row_values

HUMAN, SHARED, MACHINE = int(Authority.HUMAN), int(Authority.SHARED), int(Authority.MACHINE)
TRACKING, HAZARD_LAW = int(LawRole.TRACKING), int(LawRole.HAZARD)


@dataclass
class ArbiterArrays:
    """sharing.ArbiterState per robot, arrays of shape (N,)."""

    latched: np.ndarray
    group: np.ndarray
    role: np.ndarray
    k_h: np.ndarray
    machine_time: np.ndarray
    switches: np.ndarray
    group_switches: np.ndarray
    held: np.ndarray            # (N, P) bool: sharing.ArbiterState.held_rows over the table's distinct rows

    @staticmethod
    def initial(params: SharingParameters, N: int, P: int) -> "ArbiterArrays":
        machine = params.mode is Mode.MACHINE
        return ArbiterArrays(
            np.full(N, machine), np.full(N, -1), np.full(N, TRACKING), np.full(N, 0.0 if machine else 1.0),
            np.zeros(N), np.zeros(N, dtype=np.int64), np.zeros(N, dtype=np.int64), np.zeros((N, P), bool),
        )

    def take(self, index) -> "ArbiterArrays":
        return ArbiterArrays(*(getattr(self, f)[index] for f in self.__dataclass_fields__))


@dataclass
class Decisions:
    """sharing.Decision per robot."""

    authority: np.ndarray
    group: np.ndarray
    role: np.ndarray
    k_h: np.ndarray
    k_f: np.ndarray
    overall: np.ndarray
    group_changed: np.ndarray
    role_changed: np.ndarray

    def __post_init__(self):
        # u_s = w_h u_h + w_f u_f: (1, 0) for HUMAN, (0, 1) for MACHINE, (k_h, k_f) for SHARED
        human, machine = self.authority == HUMAN, self.authority == MACHINE
        self.human_weight = np.where(human, 1.0, np.where(machine, 0.0, self.k_h))[None]
        self.machine_weight = np.where(human, 0.0, np.where(machine, 1.0, self.k_f))[None]


def arbitrate(table: GroupTable, params: SharingParameters, state: ArbiterArrays, situation: Situation,
              row_x: np.ndarray, missed: np.ndarray, chosen: np.ndarray, intent: np.ndarray, dt: float,
              push_away: np.ndarray | None = None, pushes: np.ndarray | None = None, raw_x: np.ndarray | None = None,
              power: np.ndarray | None = None):
    """One sample of the sharing function for every robot; returns (new state, decisions).

    `row_x` (P, N) is k q + t of every distinct row, `missed` (G, N) the hazardous rows each group
    misses and `chosen` (N,) the result of select_group for this sample — or a function that gives it
    for the robots of a mask (N,) bool (−1 elsewhere), asked only for the robots whose group is chosen
    anew; `push_away` (N,): has each operator's push turned away (sharing.push_turned_away; None:
    unknown, release in the safe set only); `pushes` (P, N): k_j u_h of every distinct row, `raw_x` (P, N) their
    k q + t unmoved by the stop, `power` (N,) v·u_h (None: unknown, no row is pushed; the machine keeps authority
    while u_h pushes at a held row in every region containing q: sharing._pushes_at).
    """
    N = intent.size
    overall = situation.overall
    mode = params.mode
    if mode is Mode.HUMAN:
        none = np.full(N, -1)
        return state, Decisions(np.full(N, HUMAN), none, np.full(N, TRACKING), np.ones(N), np.zeros(N), overall,
                                np.zeros(N, bool), np.zeros(N, bool))
    hazard = overall == HAZARD
    safe = overall == SAFE
    wish_ok = np.zeros(N, bool) if push_away is None else push_away
    arange = np.arange(N)

    # k_s: the Schmitt trigger
    before = state.latched
    if pushes is None or not params.hold_pushed_faces:
        pushing = np.zeros(N, bool)
    else:
        row_pushed = (pushes > 0.0) | ((raw_x <= -params.bands.b2) & (power > 0.0)[None])
        pushed = (table.region_sel @ (state.held.T & row_pushed)) > 0.0      # (R, N): a held row pushed
        containing = situation.containing
        pushing = containing.any(axis=0) & np.all(~containing | pushed, axis=0)
    machine_time = np.where(before, state.machine_time + dt, 0.0)
    if mode is Mode.MACHINE:
        latched = np.ones(N, bool)
    else:
        machine_time = np.where(hazard & ~before, 0.0, machine_time)
        release = ~hazard & (machine_time >= params.min_machine_dwell) & (safe | wish_ok) & ~pushing
        latched = (before | hazard) & ~release
    switches = state.switches + ((latched != before) & (mode is Mode.SHARED))

    # law role, with the law-level trigger: back to tracking when safe and clear of the faces
    old = state.group
    has_old = old >= 0
    old_safe = np.where(has_old, old, 0)
    clear = np.ones(N, bool)
    for x in group_row_values(table, row_x, old_safe):        # the rows of the old group
        clear &= x <= -params.bands.b1
    clear |= ~has_old
    role = np.where(hazard, HAZARD_LAW, state.role)
    role = np.where((state.role == HAZARD_LAW) & safe & clear, TRACKING, role)

    # group: keep it unless it stopped applying or covering the hazardous rows
    if mode is Mode.MACHINE:
        needs = np.ones(N, bool)
    else:
        needs = latched
    applies = situation.containing.take(table.region_of.take(old_safe) * N + arange)
    stale = ~has_old | (latched & ~before) | ~applies | (missed.take(old_safe * N + arange) > 0)
    if callable(chosen):
        chosen = chosen(needs & stale)
    group = np.where(needs & stale & (chosen >= 0), chosen, old)
    group_changed = group != old

    # weights
    machine = np.full(N, mode is Mode.MACHINE) | hazard
    target = (wish_ok & ~pushing).astype(float)
    blend = state.k_h + (target - state.k_h) * (1.0 - math.exp(-dt / params.blend_time_constant))
    k_h = np.where(~latched, 1.0, np.where(machine, 0.0, blend))
    authority = np.where(~latched, HUMAN, np.where(k_h == 0.0, MACHINE, SHARED))

    # the rows hazardous since the take-over, of the regions containing q (sharing._with_hazard_rows)
    if mode is Mode.SHARED:
        kept = state.held & (latched & before)[:, None]
        hazardous = situation.hazard_rows & ((table.region_sel.T @ situation.containing) > 0.0)
        held = kept | (hazardous & (latched & hazard)[None]).T
    else:
        held = np.zeros_like(state.held)
    new = ArbiterArrays(latched, group, role, k_h, np.where(latched, machine_time, 0.0), switches,
                        state.group_switches + (group_changed & has_old), held)
    return new, Decisions(authority, group, role, k_h, 1.0 - k_h, overall, group_changed, role != state.role)
