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

from dataclasses import dataclass

import numpy as np

from .constraints import ConstraintGroup, GroupStack
from .reference import ReferenceShape, saturate


@dataclass(frozen=True)
class Desired:
    """The operator's desired trajectory sample: q_d, q̇_d, q̈_d."""

    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray


@dataclass(frozen=True)
class GroupCoordinates:
    """Everything the machine laws need about one group at one instant."""

    x: np.ndarray          # K q + T  (< 0 inside)
    x_dot: np.ndarray      # K v
    x_r: np.ndarray        # projected reference (< 0)
    x_r_dot: np.ndarray
    x_r_ddot: np.ndarray
    z: np.ndarray          # ln(x / x_r)
    q_r: np.ndarray        # K⁻¹ (x_r − T): the projected reference configuration
    v_r: np.ndarray        # K⁻¹ ẋ_r

    @property
    def inside(self) -> bool:
        return all(xj < 0.0 for xj in self.x.tolist())


def coordinates(group: ConstraintGroup, q: np.ndarray, v: np.ndarray, desired: Desired, shape: ReferenceShape) -> GroupCoordinates:
    """Evaluate (6)–(7) for one group. z is NaN where x ≥ 0 (the group does not apply).

    One product K·[q, v, q_d, q̇_d, q̈_d] gives x, ẋ and m, ṁ, m̈ of projected_reference (same formulas)."""
    products = group.K @ np.array([q, v, desired.q, desired.q_dot, desired.q_ddot]).T
    x = products[:, 0] + group.T
    m_dot = products[:, 3]
    x_r, d1, d2 = saturate(products[:, 2] + group.T, shape)
    x_r_dot = d1 * m_dot
    if all(xj < 0.0 for xj in x.tolist()):
        z = np.log(x / x_r)
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            z = np.log(x / x_r)
    back = group.K_inv @ np.array([x_r - group.T, x_r_dot]).T
    return GroupCoordinates(
        x=x, x_dot=products[:, 1], x_r=x_r, x_r_dot=x_r_dot, x_r_ddot=d2 * m_dot**2 + d1 * products[:, 4], z=z,
        q_r=back[:, 0], v_r=back[:, 1],
    )


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
    inertia (the true M is unknown to the machine); sharing.py picks its least.
    """
    groups = GroupsAtOnce.evaluate(stack, q, v, desired, shape, lam)
    return groups.q_r, groups.value


@dataclass(frozen=True)
class GroupsAtOnce:
    """Every group evaluated together (all_groups), keeping what `coordinates` needs for any one of them.

    One product with the stacked rows (K_rows · [q, q_d, q̇_d, v, q̈_d]) gives every group's x, m, ṁ,
    ẋ, m̈; one stacked product applies every group's K⁻¹. Rows of groups that do not apply get
    z = 0 here (their value is +∞ whatever z is), so no NaN is formed; `coordinates(g)` restores
    the NaN of `coordinates` for such a group.
    """

    stack: GroupStack
    shape_n: tuple[int, int]
    products: np.ndarray      # (G·n, 5): K q, K q_d, K q̇_d, K v, K q̈_d
    x: np.ndarray
    x_r: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    x_r_dot: np.ndarray
    z: np.ndarray
    q_r: np.ndarray           # (G, n)
    value: np.ndarray         # (G,)

    @staticmethod
    def evaluate(stack: GroupStack, q, v, desired: Desired, shape: ReferenceShape, lam: float) -> "GroupsAtOnce":
        G, n = stack.T.shape
        products = stack.K_rows @ np.array([q, desired.q, desired.q_dot, v, desired.q_ddot]).T
        x = products[:, 0] + stack.T_rows
        x_r, d1, d2 = saturate(products[:, 1] + stack.T_rows, shape)
        x_r_dot = d1 * products[:, 2]
        below = x < 0.0
        z = np.log(np.where(below, x / x_r, 1.0))
        lifted = np.empty((G, n, 2))
        lifted[:, :, 0] = ((1.0 + lam) * z + np.exp(z) * x_r_dot).reshape(G, n)
        lifted[:, :, 1] = (x_r - stack.T_rows).reshape(G, n)
        mapped = stack.K_inv @ lifted                                           # (G, n, 2): K⁻¹ per group
        p = v - mapped[:, :, 0]
        value = 0.5 * ((z * z).reshape(G, n).sum(axis=1) + (p * p).sum(axis=1))
        value[~below.reshape(G, n).all(axis=1)] = np.inf
        return GroupsAtOnce(stack, (G, n), products, x, x_r, d1, d2, x_r_dot, z, mapped[:, :, 1], value)

    def coordinates(self, g: int, group: ConstraintGroup) -> GroupCoordinates:
        """`coordinates(group, q, v, desired, shape)` for group g (= `group`), from what is already computed."""
        n = self.shape_n[1]
        rows = slice(g * n, (g + 1) * n)
        x, x_r, x_r_dot = self.x[rows], self.x_r[rows], self.x_r_dot[rows]
        if all(xj < 0.0 for xj in x.tolist()):
            z = self.z[rows]
        else:
            with np.errstate(invalid="ignore", divide="ignore"):
                z = np.log(x / x_r)
        m_dot, m_ddot = self.products[rows, 2], self.products[rows, 4]
        return GroupCoordinates(
            x=x, x_dot=self.products[rows, 3], x_r=x_r, x_r_dot=x_r_dot,
            x_r_ddot=self.d2[rows] * m_dot**2 + self.d1[rows] * m_ddot, z=z,
            q_r=self.q_r[g], v_r=group.K_inv @ x_r_dot,
        )
