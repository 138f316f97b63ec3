"""A two-link planar arm under gravity: the second Euler–Lagrange system.

It exists to show the controllers are model-agnostic: position-dependent inertia,
non-zero Ṁ and gravity exercise every term the omnidirectional robot leaves at zero.

q = [q1, q2] (rad), joint 1 from the horizontal, joint 2 relative to link 1; gravity
acts along −y. With s2 = sin q2, c2 = cos q2 and the standard parameterisation
θ = [θ1, θ2, θ3, θ4, θ5] = [m1 lc1² + m2(l1² + lc2²) + I1 + I2, m2 l1 lc2, m2 lc2² + I2,
(m1 lc1 + m2 l1) g0, m2 lc2 g0]:
M = [[θ1 + 2θ2 c2, θ3 + θ2 c2], [θ3 + θ2 c2, θ3]],
C = θ2 s2 [[−q̇2, −(q̇1 + q̇2)], [q̇1, 0]],
g = [θ4 cos q1 + θ5 cos(q1 + q2), θ5 cos(q1 + q2)].
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .base import EulerLagrangeModel


@dataclass(frozen=True)
class PlanarArmParameters:
    """Link masses (kg), lengths (m), centre-of-mass distances (m), inertias (kg m²), gravity (m/s²)."""

    mass1: float = 1.0
    mass2: float = 0.8
    length1: float = 0.5
    com1: float = 0.25
    com2: float = 0.2
    inertia1: float = 0.02
    inertia2: float = 0.012
    gravity: float = 9.81

    def theta(self) -> np.ndarray:
        p = self
        return np.array(
            [
                p.mass1 * p.com1**2 + p.mass2 * (p.length1**2 + p.com2**2) + p.inertia1 + p.inertia2,
                p.mass2 * p.length1 * p.com2,
                p.mass2 * p.com2**2 + p.inertia2,
                (p.mass1 * p.com1 + p.mass2 * p.length1) * p.gravity,
                p.mass2 * p.com2 * p.gravity,
            ]
        )


@dataclass(frozen=True)
class PlanarArm(EulerLagrangeModel):
    """Two-link arm, `kind = "arm2"` in scenario files."""

    parameters: PlanarArmParameters = field(default_factory=PlanarArmParameters)
    n = 2
    n_theta = 5
    coordinate_names = ("q1", "q2")
    parameter_names = ("theta1", "theta2", "theta3", "theta4", "theta5")
    # The physical box: each term at most about three times the default arm's θ = (0.327, 0.080, 0.044,
    # 6.38, 1.57) — a payload at the tip of up to ~1 kg with room to spare; the trust box: 1.5 times it.
    # A box of "any arm up to 10 kg and 2 m" let θ̂ wander to 60 times the inertia, and the sampled
    # loop at 500 Hz and 1 kHz went unstable (tests/test_fault_envelope_properties.py). 0 admits
    # θ̂(0) = 0. docs/control.md §11
    theta_lower = (0.0, 0.0, 0.0, 0.0, 0.0)
    theta_upper = (1.0, 0.25, 0.14, 20.0, 5.0)
    theta_band_lower = (0.0, 0.0, 0.0, 0.0, 0.0)
    theta_band_upper = (0.5, 0.12, 0.07, 9.6, 2.4)
    # link inertias are ~0.1 kg m²: the omnidirectional robot's gains would be stiff here,
    # and so would its adaptation rate (Y grows like 1/|x| near a joint limit)
    default_gains = {
        "ce": {"Kp": 5.0, "lam": 1.5, "gamma_theta": 5.0},
        "nce": {"gamma_n": 20.0},
        "of": {"stiffness": 3.0},
        "of_barrier": {"Kp": 10.0, "gamma_theta": 5.0, "barrier_weight": 0.2},
    }

    @property
    def theta(self) -> np.ndarray:
        return self.parameters.theta()

    def mass_regressor(self, q, a):
        c2 = math.cos(q[1])
        return np.array(
            [
                [a[0], (2.0 * a[0] + a[1]) * c2, a[1], 0.0, 0.0],
                [0.0, a[0] * c2, a[0] + a[1], 0.0, 0.0],
            ]
        )

    def coriolis_regressor(self, q, v, w):
        s2 = math.sin(q[1])
        return np.array(
            [
                [0.0, s2 * (-v[1] * w[0] - (v[0] + v[1]) * w[1]), 0.0, 0.0, 0.0],
                [0.0, s2 * v[0] * w[0], 0.0, 0.0, 0.0],
            ]
        )

    def gravity_regressor(self, q):
        c1, c12 = math.cos(q[0]), math.cos(q[0] + q[1])
        return np.array([[0.0, 0.0, 0.0, c1, c12], [0.0, 0.0, 0.0, 0.0, c12]])

    def mass_rate_regressor(self, q, v, b):
        # dM/dt = −θ2 s2 q̇2 [[2, 1], [1, 0]]
        s2 = math.sin(q[1])
        k = -s2 * v[1]
        return np.array([[0.0, k * (2.0 * b[0] + b[1]), 0.0, 0.0, 0.0], [0.0, k * b[0], 0.0, 0.0, 0.0]])
