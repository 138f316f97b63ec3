"""The two-link arm's fail-safe stop (docs/control.md §10, "The arm's stop").

Three things the backup-safe sets need of the arm (models/planar_arm.py), all from θ alone:

* `ArmBounds`: bounds of its model over every q — the eigenvalues of M, the gravity
  torques, and the norms of M⁻¹ times the model's pieces that the hold's deviation needs;
* `ArmBounds.braking_deceleration`: the a_c of one brake block over both joints (deflection π,
  k = 0) that the joint brakes guarantee: from ‖q̇₀‖ the joint-space path to rest is at most
  ‖q̇₀‖²/(2a_c);
* `ArmHoldDeviation`: while a torque u is held (the drives' watchdog time), how far the motion
  departs from the constant acceleration a₀ = M⁻¹(u − Cv − g) it starts with.

M depends on q2 alone (M = M̄ + θ2 cos q2 P, P = [[2, 1], [1, 0]], ‖P‖ = 1 + √2): every bound over
q is a maximum over q2 ∈ [−π, π], taken on a grid of spacing h and corrected for what lies
between grid points, so each is proven rather than sampled: λ(M) moves by at most θ2‖P‖|Δq2|
(Weyl), and f(q2) = ‖M⁻¹X‖ for a fixed X has |f′| ≤ ‖M⁻¹‖‖M′‖f ≤ κ f with κ = θ2‖P‖/m_min, so
within h/2 of a grid point f is at most e^{κh/2} times its value there. Pure: no clocks, no I/O.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: q2 samples over [−π, π] for the bounds over q (spacing 3.1e-4 rad)
GRID = 20001
#: ‖P‖ for P = [[2, 1], [1, 0]] (∂M/∂cos q2 = θ2 P)
P_NORM = 1.0 + math.sqrt(2.0)
#: κ_Q ≥ ‖Q(x, y)‖ over unit x, y, where C(q, v)v = θ2 sin q2 Q(v, v) and Q(x, y) = (−x1y2 − x2y1 − x2y2, x1y1)
#: is bilinear and symmetric: its first component is xᵀAy with ‖A‖ = (1 + √5)/2, its second is at most 1
CORIOLIS_FORM = math.sqrt(((1.0 + math.sqrt(5.0)) / 2.0) ** 2 + 1.0)


@dataclass(frozen=True)
class ArmBounds:
    """Bounds over every q of the two-link arm's model with parameters θ (planar_arm.py)."""

    theta: tuple
    inertia_min: float          # m_min ≤ λ_min(M(q))
    inertia_max: float          # m_max ≥ λ_max(M(q))
    gravity_max: tuple          # G_i = max_q |g_i(q)|: (θ4 + θ5, θ5)
    inverse_rate: float         # ν_P ≥ max_q ‖M⁻¹P‖
    inverse_sine: float         # μ ≥ max_q |sin q2| ‖M⁻¹‖
    gravity_stiffness: float    # Γ ≥ θ4 max_q ‖M⁻¹e1‖ + √2 θ5 max_q ‖M⁻¹(1, 1)‖

    @staticmethod
    def of(theta, grid: int = GRID) -> "ArmBounds":
        th = [float(x) for x in theta]
        t1, t2, t3, t4, t5 = th
        q2 = np.linspace(-math.pi, math.pi, grid)
        half = math.pi / (grid - 1)                         # h/2: every q2 is within it of a grid point
        c2 = np.cos(q2)
        m11, m12, m22 = t1 + 2.0 * t2 * c2, t3 + t2 * c2, np.full_like(c2, t3)
        mean, radius = 0.5 * (m11 + m22), np.sqrt(0.25 * (m11 - m22) ** 2 + m12 * m12)
        drift = t2 * P_NORM * half                           # Weyl: λ moves at most θ2‖P‖|Δq2|
        inertia_min = float(np.min(mean - radius)) - drift
        inertia_max = float(np.max(mean + radius)) + drift
        if not inertia_min > 0.0:
            raise ValueError("the arm's inertia matrix must be positive definite for every q")
        grow = math.exp(t2 * P_NORM / inertia_min * half) * (1.0 + 1e-12)   # e^{κh/2}, and rounding
        det = m11 * m22 - m12 * m12
        inv = np.stack([np.stack([m22, -m12], -1), np.stack([-m12, m11], -1)], -2) / det[:, None, None]
        rate = _largest_singular_value(inv @ np.array([[2.0, 1.0], [1.0, 0.0]]))
        inverse_norm = np.minimum(1.0 / (mean - radius) * grow, 1.0 / inertia_min)
        sine = (np.abs(np.sin(q2)) + half) * inverse_norm
        e1 = np.linalg.norm(inv[:, :, 0], axis=1)
        ones = np.linalg.norm(inv[:, :, 0] + inv[:, :, 1], axis=1)
        return ArmBounds(
            tuple(th), inertia_min, inertia_max, (t4 + t5, t5),
            float(np.max(rate)) * grow, float(np.max(sine)),
            (t4 * float(np.max(e1)) + math.sqrt(2.0) * t5 * float(np.max(ones))) * grow,
        )

    def braking_deceleration(self, brake_torque) -> float:
        """a_c with which the joint brakes (Coulomb torques c_i, holding at rest) bound the stop:
        a_c = min_i (c_i − G_i) / m_max (docs/control.md §10). The kinetic energy K falls at least at
        Σ_i (c_i − G_i)|q̇_i| ≥ min_i (c_i − G_i) ‖q̇‖, so the joint-space path to rest is at most
        K₀ / min_i (c_i − G_i) ≤ m_max ‖q̇₀‖² / (2 min_i (c_i − G_i)). Needs c_i > G_i: each brake
        holds its joint against the largest gravity torque it can carry."""
        c = [float(x) for x in brake_torque]
        if len(c) != 2 or not all(math.isfinite(x) for x in c):
            raise ValueError("the arm needs one finite brake torque per joint")
        spare = min(ci - gi for ci, gi in zip(c, self.gravity_max))
        if spare <= 0.0:
            raise ValueError("each joint's brake must exceed its largest gravity torque, "
                             f"({self.gravity_max[0]:.4g}, {self.gravity_max[1]:.4g}) N·m; got ({c[0]:g}, {c[1]:g})")
        return spare / self.inertia_max


def _largest_singular_value(A: np.ndarray) -> np.ndarray:
    """σ_max of each 2×2 matrix of A (…, 2, 2): σ² = (F + √(F² − 4 det²))/2, F = ‖A‖_F²."""
    frob = np.sum(A * A, axis=(-2, -1))
    det = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    return np.sqrt(0.5 * (frob + np.sqrt(np.maximum(frob * frob - 4.0 * det * det, 0.0))))


@dataclass(frozen=True)
class ArmHoldDeviation:
    """The hold's departure from constant acceleration: called with (‖v₀‖, ‖a₀‖, T) it returns
    (x, y) with ‖q(t) − q₀ − v₀t − ½a₀t²‖ ≤ x and ‖q̇(t) − v₀ − a₀t‖ ≤ y for every t ∈ [0, T], for
    any q₀ and any held torque u whose initial acceleration M(q₀)⁻¹(u − C(q₀, v₀)v₀ − g(q₀)) has norm
    ‖a₀‖ ((inf, inf) when no bound follows). Nondecreasing in each argument.

    With d(t) = q(t) − q₀ − v₀t − ½a₀t², Δq = q(t) − q₀ and Δv = q̇(t) − v₀, M a = u − Cv − g gives
    d̈ = a(t) − a₀ = M⁻¹(M₀ − M)a₀ + M⁻¹(C₀v₀ − Cv) + M⁻¹(g₀ − g) (M, C, g at the time t), and
    ‖M⁻¹(M₀ − M)a₀‖ ≤ θ2 ν_P |Δq2| ‖a₀‖, ‖M⁻¹(C₀v₀ − Cv)‖ ≤ θ2 κ_Q (|Δq2| ‖v₀‖²/m_min +
    μ‖Δv‖(2‖v₀‖ + ‖Δv‖)) (Cv = θ2 sin q2 Q(v, v), Q bilinear, ‖Q‖ ≤ κ_Q), ‖M⁻¹(g₀ − g)‖ ≤ Γ‖Δq‖;
    with ‖Δq‖ ≤ ‖v₀‖t + ½‖a₀‖t² + ‖d‖ and ‖Δv‖ ≤ ‖a₀‖t + ‖ḋ‖:

        ‖d̈(t)‖ ≤ R(t, ‖d‖, ‖ḋ‖) = L (‖v₀‖t + ½‖a₀‖t² + x) + c (‖a₀‖t + y)(2‖v₀‖ + ‖a₀‖t + y),
        L = θ2 ν_P ‖a₀‖ + θ2 κ_Q ‖v₀‖²/m_min + Γ,   c = θ2 κ_Q μ,

    R increasing in t, x, y. The bounds come from implicit Euler on ẋ = y, ẏ = R(t, x, y) over
    `steps` steps of T/steps: y_{k+1} = y_k + h R(t_{k+1}, x_k + h y_{k+1}, y_{k+1}) (the smallest
    root of a quadratic), x_{k+1} = x_k + h y_{k+1}. Every quantity grows over a step, so its
    right-end value majorises the step (ȳ = ∫‖d̈‖ and x̄ = ∫ȳ stay below (x, y) by continuity), and the
    result is an upper bound, not an estimate. tests/test_arm_backup.py checks it against RK4."""

    mass_rate: float          # θ2 ν_P
    coriolis_shift: float     # θ2 κ_Q / m_min
    coriolis: float           # θ2 κ_Q μ
    gravity: float            # Γ
    steps: int = 8

    @staticmethod
    def of(bounds: ArmBounds, steps: int = 8) -> "ArmHoldDeviation":
        t2 = bounds.theta[1]
        return ArmHoldDeviation(t2 * bounds.inverse_rate, t2 * CORIOLIS_FORM / bounds.inertia_min,
                                t2 * CORIOLIS_FORM * bounds.inverse_sine, bounds.gravity_stiffness, steps)

    def __call__(self, speed: float, accel: float, duration: float) -> tuple[float, float]:
        if duration <= 0.0 or (speed <= 0.0 and accel <= 0.0):
            return 0.0, 0.0
        V, A = speed, accel
        L = self.mass_rate * A + self.coriolis_shift * V * V + self.gravity
        c = self.coriolis
        h = duration / self.steps
        x = y = 0.0
        for k in range(1, self.steps + 1):
            t = k * h
            shift, dv, top = V * t + 0.5 * A * t * t, A * t, 2.0 * V + A * t
            a2 = h * c
            a1 = 1.0 - h * h * L - a2 * (dv + top)
            a0 = y + h * L * (shift + x) + a2 * dv * top
            disc = a1 * a1 - 4.0 * a2 * a0
            if not (a1 > 0.0 and disc >= 0.0):
                return math.inf, math.inf
            y = 2.0 * a0 / (a1 + math.sqrt(disc))
            x = x + h * y
        return x * (1.0 + 1e-9), y * (1.0 + 1e-9)
