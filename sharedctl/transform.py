"""The logarithmic coordinate transform of one constraint group (paper (6), (8)–(11)).

With x = K q + T < 0 and the projected reference x_r < 0 (reference.py):

    z = ln(x / x_r)                                  (6)
    ż = Z1 K v_e + Z2 K v_r,   Z1 = diag(e^{−z}/x_r) = diag(1/x),
                               Z2 = diag((e^{−z} − 1)/x_r)          (9)
    K v_e* = z + Z3 K v_r,     Z3 = diag(e^{z} − 1)                 (virtual input)
    p = v_e − v_e* − λ K⁻¹ z                                        (11)

Collecting terms, p = v − v_ref with the reference velocity

    v_ref = v_r + v_e* + λ K⁻¹ z = K⁻¹ [(1 + λ) z + e^{z} ∘ ẋ_r],

and v̇_ref = K⁻¹ [(1 + λ) ż + e^{z} ∘ ż ∘ ẋ_r + e^{z} ∘ ẍ_r]. Then
ż = Z1 K p + (λ + 1) Z1 z and M ṗ + C p + Y θ = u with Y θ = M v̇_ref + C(q, v) v_ref + g,
which is the regressor of (11). Everything here is algebra on measured q, v and the
operator's desired trajectory; docs/control.md §2 derives it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .constraints import ConstraintGroup, GroupStack
from .reference import ReferenceShape, saturate, saturate_floats
from .short_vectors import floats, matvec


@dataclass(frozen=True)
class Desired:
    """The operator's desired trajectory sample: q_d, q̇_d, q̈_d."""

    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray


class CoordinateFloats(NamedTuple):
    """One group's coordinates at one instant as lists of Python floats (see GroupCoordinates)."""

    x: list          # K q + T  (< 0 inside)
    x_dot: list      # K v
    x_r: list        # projected reference (< 0)
    x_r_dot: list
    x_r_ddot: list
    z: list          # ln(x / x_r)
    q_r: list        # K⁻¹ (x_r − T): the projected reference configuration
    v_r: list        # K⁻¹ ẋ_r


def _as_array(name: str) -> property:
    return property(lambda self: np.array(getattr(self.floats, name)), doc=f"`{name}` as a numpy array")


class GroupCoordinates:
    """Everything the machine laws need about one group at one instant.

    Held as Python floats (`floats`, what the laws compute with: short_vectors); each field is
    also an attribute giving a numpy array (c.x, c.z, c.q_r, …) for analysis and tests."""

    __slots__ = ("floats",)

    def __init__(self, floats: CoordinateFloats):
        self.floats = floats

    x, x_dot, x_r, x_r_dot, x_r_ddot, z, q_r, v_r = (_as_array(name) for name in CoordinateFloats._fields)

    @property
    def inside(self) -> bool:
        return all(xj < 0.0 for xj in self.floats.x)


def coordinates(group: ConstraintGroup, q, v, desired: Desired, shape: ReferenceShape, rows=None) -> GroupCoordinates:
    """Evaluate (6)–(7) for one group, row by row. z is NaN where x > 0 and −∞ where x = 0 (as
    np.log(x / x_r)): the group does not apply there.

    x, ẋ and m, ṁ, m̈ of projected_reference (same formulas) come from the group's rows; `rows`
    may give (x, ẋ) already computed (e.g. from FeasibleSet.row_values)."""
    f = group.floats
    K, T = f.K, f.T
    if rows is None:
        rows = [kq + t for kq, t in zip(matvec(K, floats(q)), T)], matvec(K, floats(v))
    x, x_dot = rows
    x_r, s1, s2 = saturate_floats([m + t for m, t in zip(matvec(K, desired.q.tolist()), T)], shape)
    m_dot, m_ddot = matvec(K, desired.q_dot.tolist()), matvec(K, desired.q_ddot.tolist())
    x_r_dot = [d1 * md for d1, md in zip(s1, m_dot)]
    x_r_ddot = [d2 * (md * md) + d1 * mdd for d1, d2, md, mdd in zip(s1, s2, m_dot, m_ddot)]
    z = [_log_ratio(xj, xr) for xj, xr in zip(x, x_r)]
    q_r = matvec(f.K_inv, [xr - t for xr, t in zip(x_r, T)])
    return GroupCoordinates(CoordinateFloats(list(x), list(x_dot), x_r, x_r_dot, x_r_ddot, z, q_r,
                                             matvec(f.K_inv, x_r_dot)))


def _log_ratio(x: float, x_r: float) -> float:
    """ln(x / x_r) of (6) with numpy's values off the domain: −∞ at 0, NaN below."""
    ratio = x / x_r
    if ratio > 0.0:
        return math.log(ratio)
    return -math.inf if ratio == 0.0 else math.nan


def reference_signals(c: CoordinateFloats, K, K_inv, v, lam: float):
    """(p, ż, v_ref, v̇_ref) on floats at one instant, for velocity v (floats): ż = K v/x − ẋ_r/x_r
    (equivalent to (9)), v_ref = K⁻¹[(1+λ) z + e^z ∘ ẋ_r], v̇_ref = K⁻¹[(1+λ) ż + e^z ∘ ż ∘ ẋ_r +
    e^z ∘ ẍ_r] and p = v − v_ref (11). K, K_inv: the group's rows (ConstraintGroup.floats)."""
    lam1 = 1.0 + lam
    zd, lifted_v, lifted_a = [], [], []
    for kv, xj, xr, xr_dot, xr_ddot, zj in zip(matvec(K, v), c.x, c.x_r, c.x_r_dot, c.x_r_ddot, c.z):
        zdj = kv / xj - xr_dot / xr
        ez = math.exp(zj)
        zd.append(zdj)
        lifted_v.append(lam1 * zj + ez * xr_dot)
        lifted_a.append(lam1 * zdj + ez * zdj * xr_dot + ez * xr_ddot)
    v_ref, a_ref = matvec(K_inv, lifted_v), matvec(K_inv, lifted_a)
    return [vj - rj for vj, rj in zip(v, v_ref)], zd, v_ref, a_ref


def bounded_reference_signals(c: CoordinateFloats, K, K_inv, v, lam: float):
    """(p, ż, v_ref, v̇_ref) of the output-feedback barrier law (docs/control.md §4.3) on floats, for
    velocity v (floats): with μ(z) = −λ tanh z and e^z ∘ ẋ_r = x ∘ ẋ_r/x_r,

        v_ref = K⁻¹[x ∘ (ẋ_r/x_r + μ(z))],   so Z1 K v_ref = ẋ_r/x_r + μ(z), ż = Z1 K p + μ(z),
        v̇_ref = K⁻¹[ẋ ∘ (ẋ_r/x_r + μ + μ′) − x ∘ (ẋ_r/x_r)(ẋ_r/x_r + μ′) + e^z ∘ ẍ_r],

    ẋ = K v, μ′(z) = −λ(1 − tanh² z), p = v − v_ref. The coefficient of ẋ in v̇_ref is bounded
    (|μ + μ′| ≤ 5λ/4, |ẋ_r/x_r| ≤ |ẋ_r|/ε), where (12)'s grows like (1 + λ)/|x|."""
    zd, lifted_v, lifted_a = [], [], []
    for kv, xj, xr, xr_dot, xr_ddot, zj in zip(matvec(K, v), c.x, c.x_r, c.x_r_dot, c.x_r_ddot, c.z):
        rate = xr_dot / xr
        tz = math.tanh(zj)
        mu, dmu = -lam * tz, -lam * (1.0 - tz * tz)
        zd.append(kv / xj - rate)
        lifted_v.append(xj * (rate + mu))
        lifted_a.append(kv * (rate + mu + dmu) - xj * rate * (rate + dmu) + math.exp(zj) * xr_ddot)
    v_ref, a_ref = matvec(K_inv, lifted_v), matvec(K_inv, lifted_a)
    return [vj - rj for vj, rj in zip(v, v_ref)], zd, v_ref, a_ref


def z_dot(c: GroupCoordinates, x_dot: np.ndarray) -> np.ndarray:
    """ż = ẋ/x − ẋ_r/x_r (equivalent to (9))."""
    return x_dot / c.x - c.x_r_dot / c.x_r


def reference_velocity(group: ConstraintGroup, c: GroupCoordinates, lam: float) -> np.ndarray:
    """v_ref = K⁻¹[(1+λ) z + e^z ∘ ẋ_r]; p = v − v_ref."""
    return group.K_inv @ ((1.0 + lam) * c.z + np.exp(c.z) * c.x_r_dot)


def reference_acceleration(group: ConstraintGroup, c: GroupCoordinates, zd: np.ndarray, lam: float) -> np.ndarray:
    """v̇_ref = K⁻¹[(1+λ) ż + e^z ∘ ż ∘ ẋ_r + e^z ∘ ẍ_r]."""
    ez = np.exp(c.z)
    return group.K_inv @ ((1.0 + lam) * zd + ez * zd * c.x_r_dot + ez * c.x_r_ddot)


def reference_velocity_acceleration(group: ConstraintGroup, c: GroupCoordinates, zd: np.ndarray, lam: float):
    """(v_ref, v̇_ref) of reference_velocity and reference_acceleration with one K⁻¹ product."""
    ez = np.exp(c.z)
    both = group.K_inv @ np.array([(1.0 + lam) * c.z + ez * c.x_r_dot,
                                   (1.0 + lam) * zd + ez * zd * c.x_r_dot + ez * c.x_r_ddot]).T
    return both[:, 0], both[:, 1]


def all_groups(stack: GroupStack, q: np.ndarray, v: np.ndarray, desired: Desired, shape: ReferenceShape, lam: float):
    """Every group at once: (q_r G×n, selection value G) with value = ½(|z|² + |p|²), +∞ where x ≥ 0.

    The selection value is the measurable part of each law's Lyapunov function with unit
    inertia (the true M is unknown to the machine); sharing.py picks its least. One product with
    the stacked rows (K_rows · [q, q_d, q̇_d]) gives every group's x, m, ṁ; one stacked product
    applies every group's K⁻¹. Rows of groups that do not apply get z = 0 here (their
    value is +∞ whatever z is), so no NaN is formed.
    """
    G, n = stack.T.shape
    products = stack.K_rows @ np.array([q, desired.q, desired.q_dot]).T
    x = products[:, 0] + stack.T_rows
    x_r, d1, _ = saturate(products[:, 1] + stack.T_rows, shape)
    below = x < 0.0
    z = np.log(np.where(below, x / x_r, 1.0))
    lifted = np.array([(1.0 + lam) * z + np.exp(z) * (d1 * products[:, 2]), x_r - stack.T_rows]).T
    mapped = stack.K_inv_blocks @ lifted                 # (G·n, 2): every group's v_ref and q_r
    p = v - mapped[:, 0].reshape(G, n)
    value = 0.5 * ((z * z).reshape(G, n).sum(axis=1) + (p * p).sum(axis=1))
    value[~below.reshape(G, n).all(axis=1)] = np.inf
    return mapped[:, 1].reshape(G, n), value
