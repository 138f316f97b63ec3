"""Safe, hysteresis and hazardous sets (paper Definition 2).

With f_b(x) = 1/(x + b) − 1/b (a speed allowance towards a face: +∞ at x = −b,
shrinking to 0 on the face x = 0) and b2 > b1 > 0, for one row j with value x_j < 0 and
rate ẋ_j:

* the row is *unsafe* when x_j ≥ −b2 and ẋ_j > f_b2(x_j)          (it breaks O_s)
* the row is *hazardous* when −b1 ≤ x_j < 0 and ẋ_j ≥ f_b1(x_j)   (it puts the state in O_d)

A polytope's state is SAFE when none of its rows is unsafe, HAZARD when one of its rows
is hazardous and HYSTERESIS otherwise. Because f_b2 < f_b1 on (−b1, 0), a row must cross
the whole band between the two curves to go from safe to hazardous — the room the
Schmitt trigger of sharing.py needs.

The inner band b0 (an addition to Definition 2): f_b1(x) ≈ |x|/b1² near a face, so an approach
at speed s is first hazardous only s·b1²/(1 + s·b1) from the face — 0.27 mm at 3 mm/s. A law
whose forces grow like 1/x there (every law of the paper) then acts at a distance no sampled
or numerically integrated loop can follow. Any approach within b0 of a face is therefore
hazardous too, so the machine takes over at least b0 from it. b0 < ε keeps the projected
reference (at −ε) outside the inner band.

The standoff band b_s (an addition): a row less than b_s from its face is never safe — at rest it is
in the hysteresis set. Definition 2's curves are allowances on speed only, so a state at rest is
safe however close to a face; the machine, holding off an operator who pushes out of the set, brings
the robot to rest at its projected reference ε inside the face, and with the printed sets that rest
state is safe, (46) hands authority back, the push brings the robot in again and the hand-over
oscillates. b_s > ε puts the machine's rest point in the hysteresis set, where k_s keeps its value
(sharing.py releases it when the operator's wish returns inside). b0 = b_s = 0 give Definition 2 as
printed.

For a union of polytopes (non-convex Q_a) the state is SAFE if it is safe with respect to
some polytope that contains q (the robot can stay in that one), HAZARD if it is hazardous
with respect to every polytope that contains q (it is about to leave the union), and
HYSTERESIS otherwise. See docs/control.md §5.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .constraints import FeasibleSet


class SetClass(enum.IntEnum):
    """Where the state is, from the operator's point of view."""

    SAFE = 0
    HYSTERESIS = 1
    HAZARD = 2


@dataclass(frozen=True)
class Bands:
    """b1 < b2: the widths (in constraint units, metres for unit rows) of the two bands;
    b0 < b1: the inner band in which any approach is hazardous; b0 ≤ b_s < b1: the standoff band, in
    which no state is safe (0, 0 = Definition 2 as printed)."""

    b1: float = 0.3
    b2: float = 0.6
    b0: float = 0.025
    standoff: float = 0.15

    def __post_init__(self):
        if not (0.0 < self.b1 < self.b2):
            raise ValueError(f"need 0 < b1 < b2, got b1={self.b1}, b2={self.b2}")
        if not (0.0 <= self.b0 < self.b1):
            raise ValueError(f"need 0 <= b0 < b1, got b0={self.b0}")
        if not (self.b0 <= self.standoff < self.b1):
            raise ValueError(f"need b0 <= standoff < b1, got standoff={self.standoff}")


def allowance(x: np.ndarray, b: float) -> np.ndarray:
    """f_b(x) = 1/(x + b) − 1/b for x > −b, +∞ for x ≤ −b (no limit that far out)."""
    x = np.asarray(x, dtype=float)
    out = np.full(x.shape, np.inf)
    near = x > -b
    out[near] = 1.0 / (x[near] + b) - 1.0 / b
    return out


def hazardous_rows(x: np.ndarray, x_dot: np.ndarray, bands: Bands) -> np.ndarray:
    """Boolean per row: −b1 ≤ x < 0 and ẋ ≥ f_b1(x), or −b0 ≤ x < 0 and ẋ > 0 (the inner band)."""
    near = (x < 0.0) & (x >= -bands.b1)
    return near & ((x_dot >= allowance(x, bands.b1)) | ((x >= -bands.b0) & (x_dot > 0.0)))


def unsafe_rows(x: np.ndarray, x_dot: np.ndarray, bands: Bands) -> np.ndarray:
    """Boolean per row: x ≥ −b2 and ẋ > f_b2(x), or x > −b_s (the standoff band); rows at or past the
    face count as unsafe."""
    return ((x >= -bands.b2) & (x_dot > allowance(x, bands.b2))) | (x > -bands.standoff)


def classify_rows(x: np.ndarray, x_dot: np.ndarray, bands: Bands) -> SetClass:
    """The class of one polytope (or one group) from its rows."""
    if np.any(hazardous_rows(x, x_dot, bands)):
        return SetClass.HAZARD
    if np.any(unsafe_rows(x, x_dot, bands)):
        return SetClass.HYSTERESIS
    return SetClass.SAFE


class Situation(NamedTuple):
    """The classification of one state (q, v) against a feasible set (a named tuple: one is built every sample)."""

    overall: SetClass
    containing: tuple[int, ...]             # regions that contain q
    region_class: dict[int, SetClass]       # class per containing region
    hazard_rows: dict[int, tuple[int, ...]]  # hazardous row indices per containing region


def _row_flags(x: float, x_dot: float, b0: float, b1: float, b2: float, bs: float) -> tuple[bool, bool]:
    """(hazardous, unsafe) for one row: hazardous_rows and unsafe_rows on Python floats (same arithmetic)."""
    hazardous = x < 0.0 and x >= -b1 and (
        x_dot >= (1.0 / (x + b1) - 1.0 / b1 if x > -b1 else math.inf) or (x >= -b0 and x_dot > 0.0)
    )
    unsafe = x > -bs or x > -b2 and x_dot > 1.0 / (x + b2) - 1.0 / b2      # at x ≤ −b2 the allowance is +∞
    return hazardous, unsafe


def classify_groups(feasible: FeasibleSet, q, v, bands: Bands, rows=None) -> tuple[SetClass, ...]:
    """The class of every constraint group, in group order: classify_rows on group g's rows
    x = K_g q + T_g, ẋ = K_g v, whether or not g's polytope contains q.

    Row by row on Python floats (_row_flags, as in classify). `rows` may hold
    `feasible.row_values(q, v)` already computed by the caller."""
    b0, b1, b2, bs = bands.b0, bands.b1, bands.b2, bands.standoff
    rows = feasible.row_values(q, v) if rows is None else rows
    classes = []
    for g in range(len(feasible.groups)):
        group_class = SetClass.SAFE
        for xj, dj in zip(*feasible.group_rows(g, rows)):
            hazardous, unsafe = _row_flags(xj, dj, b0, b1, b2, bs)
            if hazardous:
                group_class = SetClass.HAZARD
                break
            if unsafe:
                group_class = SetClass.HYSTERESIS
        classes.append(group_class)
    return tuple(classes)


def classify(feasible: FeasibleSet, q: np.ndarray, v: np.ndarray, bands: Bands, rows=None) -> Situation:
    """Classify (q, v) against every polytope that contains q, then the union.

    Row by row on Python floats (for a few rows faster than array operations; the same
    comparisons and arithmetic as hazardous_rows/unsafe_rows/classify_rows). `rows` may hold
    `feasible.row_values(q, v)` already computed by the caller."""
    region_class: dict[int, SetClass] = {}
    hazard: dict[int, tuple[int, ...]] = {}
    containing = []
    b0, b1, b2, bs = bands.b0, bands.b1, bands.b2, bands.standoff
    values, rates = feasible.row_values(q, v) if rows is None else rows
    for index, (first, end) in enumerate(feasible.row_spans):
        x = values[first:end]
        if not all(xj < 0.0 for xj in x):
            continue
        containing.append(index)
        rows, any_unsafe = [], False
        for j, (xj, dj) in enumerate(zip(x, rates[first:end])):
            hazardous, unsafe = _row_flags(xj, dj, b0, b1, b2, bs)
            if hazardous:
                rows.append(j)
            any_unsafe = any_unsafe or unsafe
        hazard[index] = tuple(rows)
        region_class[index] = SetClass.HAZARD if rows else SetClass.HYSTERESIS if any_unsafe else SetClass.SAFE
    if not containing:
        overall = SetClass.HAZARD
    elif any(c == SetClass.SAFE for c in region_class.values()):
        overall = SetClass.SAFE
    elif all(c == SetClass.HAZARD for c in region_class.values()):
        overall = SetClass.HAZARD
    else:
        overall = SetClass.HYSTERESIS
    return Situation(overall, tuple(containing), region_class, hazard)
