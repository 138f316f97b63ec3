"""The omnidirectional robot's fail-safe stop (docs/control.md §10, "The robot's stop").

Two things the backup-safe sets need of the robot (models/omni_robot.py), from θ = (m1, m3, a)
and the wheels' brakes and friction:

* `OmniStopBounds`: the braked path of the translation and of the yaw. The wheels' brakes are
  shared by both: a wheel's Coulomb torque c (friction plus brake) acts against its own speed
  ω_j = (a_j·v + L ψ̇)/r (a_j its rolling direction in the world, 120° apart), so a turning robot's
  translation brakes less and a braked translation turns the robot. The bound is on the kinetic
  energy K = ½(m1|v|² + m3ψ̇²): the Coriolis term does no work (vᵀCv = 0), so

      K̇ = −(c/r) Σ_j |a_j·v + Lψ̇| − (b/r²) Σ_j (a_j·v + Lψ̇)² ≤ −(c/r) max(1.5|v|, 3L|ψ̇|) − 2κK,

  since the three projections a_j·v have a range of at least 1.5|v| (and Σ|x_j + s| ≥ max x_j −
  min x_j for every shift s), their sum with 3Lψ̇ is 3Lψ̇, Σ(a_j·v)² = 1.5|v|², Σa_j = 0, and
  κ = min(3b/(2r²m1), 3bL²/(r²m3)). With S_t = √(2K/m1) (S_t ≥ |v|, so K/|v| ≥ m1S_t/2), along the
  translation's path P: S_t dS_t/dP ≤ −a_t − κS_t, a_t = 1.5c/(r m1) — the one-dimensional braking
  law v dv/dx = −(a + kv), whose path to rest from S is s(S) = S/k − (a/k²) ln(1 + kS/a). The same
  for the yaw with S_ψ = √(2K/m3) and a_ψ = 3cL/(r m3). So each block's path is s_b(S_b) with the
  block's speed replaced by its *energy speed*: S_t² = |v|² + (m3/m1)ψ̇², S_ψ² = ψ̇² + (m1/m3)|v|²,
  in any direction (no deflection cone: the yaw turns the wheels' sectors).
* `OmniHoldDeviation`: while the drives hold their last wheel torques τ, the world-frame force
  turns with the robot, u_xy(t) = R(ψ(t) − ψ₀)F₀, and the Coriolis term with ψ̇; the yaw's
  acceleration u_ψ/m3 stays constant. Its departure from the constant acceleration
  a₀ = M⁻¹(u − Cv) it starts with, per block.

Pure: no clocks, no I/O. The arithmetic of `OmniHoldDeviation` is plain +, −, × on its arguments,
so the batched governor (sharedctl/batched/backup.py) calls it on arrays and gets the same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class OmniStopBounds:
    """The braked stop of the robot with parameters θ = (m1, m3, a), wheel radius r and wheel
    distance L, per wheel a Coulomb torque `coulomb` (friction plus brake, N·m) and a viscous one
    `viscous` (N·m·s/rad)."""

    translation_deceleration: float    # a_t = 1.5c/(r m1), m/s²
    yaw_deceleration: float            # a_ψ = 3cL/(r m3), rad/s²
    viscous: float                     # κ = min(3b/(2r²m1), 3bL²/(r²m3)), 1/s
    inertia_ratio: float               # m3/m1 (m²): S_t² = |v|² + (m3/m1)ψ̇², S_ψ² = ψ̇² + (m1/m3)|v|²
    wheel_share: float                 # ρ = a/m1 ∈ [0, 1): the wheels' share of the translating inertia

    @staticmethod
    def of(theta, wheel_radius: float, wheel_distance: float, coulomb: float, viscous: float) -> "OmniStopBounds":
        m1, m3, a = (float(x) for x in theta)
        r, L = float(wheel_radius), float(wheel_distance)
        if not (m1 > 0.0 and m3 > 0.0 and 0.0 <= a < m1 and r > 0.0 and L > 0.0 and coulomb > 0.0 and viscous >= 0.0):
            raise ValueError("the robot's stop needs m1, m3, r, L, c > 0, b >= 0 and 0 <= a < m1")
        return OmniStopBounds(1.5 * coulomb / (r * m1), 3.0 * coulomb * L / (r * m3),
                              min(3.0 * viscous / (2.0 * r * r * m1), 3.0 * viscous * L * L / (r * r * m3)),
                              m3 / m1, a / m1)

    def hold_deviation(self) -> "OmniHoldDeviation":
        return OmniHoldDeviation(self.wheel_share)


@dataclass(frozen=True)
class OmniHoldDeviation:
    """The held wheel torques' departure from constant acceleration, per block (translation, yaw).

    `by_block((s_t, s_ψ), (α_t, α_ψ), T)` with s_t ≥ |v₀,xy|, s_ψ ≥ |ψ̇₀|, α_t ≥ |a₀,xy|, α_ψ ≥ |a₀,ψ|
    returns ((x_t, 0), (y_t, 0)): |q_xy(t) − q₀ − v₀t − ½a₀t²| ≤ x_t and |v_xy(t) − v₀ − a₀t| ≤ y_t for
    t ∈ [0, T]; the yaw is exact (u_ψ is constant and C has no yaw row). Nondecreasing in every argument.

    Proof. With ρ = a/m1 the translation obeys v̇ = F(t)/m1 + ρψ̇ R₉₀ v, F(t) = R(Δψ(t))F₀, Δψ(t) =
    ψ̇₀t + ½a₀,ψt² (exact). Writing v = R(ρΔψ)w gives ẇ = R((1 − ρ)Δψ)F₀/m1, so

        v(t) = R(ρΔψ(t)) [v₀ + (1/m1) ∫₀ᵗ R((1 − ρ)Δψ(s)) F₀ ds],   a₀,xy = F₀/m1 + ρψ̇₀ R₉₀ v₀.

    With Φ(t) = s_ψt + ½α_ψt² ≥ |Δψ(t)|, |e^{iφ} − 1 − iφ| ≤ φ²/2, |e^{iφ} − 1| ≤ |φ| and
    G = α_t + ρ s_ψ s_t ≥ |F₀|/m1:

        |v(t) − v₀ − a₀t| ≤ s_t (½ρ²Φ(t)² + ½ρα_ψt²) + G (ρtΦ(t) + (1 − ρ)∫₀ᵗΦ) = y(t),

    a polynomial, nondecreasing in t; x(t) = ∫₀ᵗ y in closed form. tests/test_backup.py checks both
    against RK4 of the plant without friction."""

    wheel_share: float      # ρ = a/m1

    def by_block(self, speeds, accelerations, duration):
        s, w = speeds
        alpha, beta = accelerations
        x, y = hold_deviation_bounds(self.wheel_share, s, w, alpha, beta, duration)
        return (x, 0.0 * x), (y, 0.0 * y)

    def acceleration_spread(self, speeds, slacks):
        """Per block, the most a₀ = M⁻¹(u − C(v)v) changes for a fixed u when v moves by at most
        `slacks` (ε_t, ε_ψ) from a velocity with block speeds `speeds` (s_t, s_ψ): only the Coriolis
        term depends on v, ρ|ψ̇′R₉₀v′ − ψ̇R₉₀v| ≤ ρ(ε_ψ(s_t + ε_t) + s_ψε_t); the yaw's none."""
        s, w = speeds
        e, f = slacks
        spread = self.wheel_share * (f * (s + e) + w * e)
        return spread, 0.0 * spread


def hold_deviation_bounds(rho, s, w, alpha, beta, T):
    """(x(T), y(T)) of `OmniHoldDeviation` for ρ, translation and yaw speeds s, w, acceleration bounds α,
    β: plain arithmetic, so the same function runs on floats, on arrays and compiled
    (sharedctl/batched/compiled_backup.py)."""
    T2 = T * T
    T3 = T2 * T
    phi = w * T + 0.5 * beta * T2
    G = alpha + rho * w * s
    y = s * (0.5 * rho * rho * phi * phi + 0.5 * rho * beta * T2) + G * (
        rho * T * phi + (1.0 - rho) * (0.5 * w * T2 + beta * T3 / 6.0))
    phi2 = w * w * T3 / 3.0 + w * beta * T2 * T2 / 4.0 + beta * beta * T3 * T2 / 20.0     # ∫₀ᵀ Φ²
    x = s * (0.5 * rho * rho * phi2 + rho * beta * T3 / 6.0) + G * (
        rho * (w * T3 / 3.0 + beta * T2 * T2 / 8.0) + (1.0 - rho) * (w * T3 / 6.0 + beta * T2 * T2 / 24.0))
    return x, y


def energy_weights(bounds: OmniStopBounds) -> tuple[tuple[float, float], tuple[float, float]]:
    """The weights of (|v|², ψ̇²) in S_t² and in S_ψ²."""
    return (1.0, bounds.inertia_ratio), (1.0 / bounds.inertia_ratio, 1.0)

