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
from .reference import ReferenceShape, projected_reference, saturate


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
        return bool(np.all(self.x < 0.0))


def coordinates(group: ConstraintGroup, q: np.ndarray, v: np.ndarray, desired: Desired, shape: ReferenceShape) -> GroupCoordinates:
    """Evaluate (6)–(7) for one group. z is NaN where x ≥ 0 (the group does not apply)."""
    x = group.K @ q + group.T
    x_dot = group.K @ v
    x_r, x_r_dot, x_r_ddot = projected_reference(group.K, group.T, desired.q, desired.q_dot, desired.q_ddot, shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.log(x / x_r)
    return GroupCoordinates(
        x=x, x_dot=x_dot, x_r=x_r, x_r_dot=x_r_dot, x_r_ddot=x_r_ddot, z=z,
        q_r=group.K_inv @ (x_r - group.T), v_r=group.K_inv @ x_r_dot,
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


def all_groups(stack: GroupStack, q: np.ndarray, v: np.ndarray, desired: Desired, shape: ReferenceShape, lam: float):
    """Every group at once: (q_r G×n, selection value G) with value = ½(|z|² + |p|²), +∞ where x ≥ 0.

    The selection value is the measurable part of each law's Lyapunov function with unit
    inertia (the true M is unknown to the machine); sharing.py picks its least.
    """
    x = stack.K @ q + stack.T
    m = stack.K @ desired.q + stack.T
    x_r, d1, _ = saturate(m, shape)
    x_r_dot = d1 * (stack.K @ desired.q_dot)
    inside = np.all(x < 0.0, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.log(x / x_r)
    v_ref = np.einsum("gij,gj->gi", stack.K_inv, (1.0 + lam) * z + np.exp(z) * x_r_dot)
    p = v - v_ref
    value = 0.5 * (np.sum(z * z, axis=1) + np.sum(p * p, axis=1))
    value[~inside] = np.inf
    q_r = np.einsum("gij,gj->gi", stack.K_inv, x_r - stack.T)
    return q_r, value
