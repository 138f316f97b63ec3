"""The plant models against their physics, built here independently of the regressors.

* Omnidirectional robot: Newton–Euler for the body and each wheel (the paper's three wheels
  120° apart at L_r from the centre), with the wheel accelerations by finite differences. Not
  the Lagrangian with the rolling constraints substituted into T: omni-wheel rolling is a
  nonholonomic constraint, and substituting it before differentiating loses the term that
  turns the wheels' drive directions with the body — the C = a ψ̇ [[0, 1, 0], [−1, 0, 0], [0, 0, 0]]
  of the model (the substituted T is independent of ψ and gives C = 0).
* Two-link arm (holonomic): the Lagrangian from the links' centre-of-mass positions — M from
  the kinetic energy, C from the Christoffel symbols of M, g from the potential energy, each by
  finite differences.
* Passivity (Ṁ − 2C skew-symmetric), with Ṁ by finite differences; energy conserved with u = 0;
  the wheel map's power balance.
"""
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sharedctl.models import OmniRobot, PlanarArm

finite = st.floats(-3.0, 3.0, allow_nan=False)
vec3 = st.lists(finite, min_size=3, max_size=3).map(np.array)
vec2 = st.lists(finite, min_size=2, max_size=2).map(np.array)


# ----- the omnidirectional robot: Newton–Euler -------------------------------------------------
def omni_force_newton_euler(p, q, v, a, h=1e-5):
    """The generalised force u that gives the robot acceleration q̈ = a at (q, q̇ = v).

    Wheel k drives along d_k = (cos φ_k, sin φ_k), φ_k = ψ + 2πk/3 (the body's tangent at the
    wheel), and spins at ω_k = (d_k·(ẋ, ẏ) + L_r ψ̇)/r. With f_k the traction force along d_k:
    wheel I_r ω̇_k = τ_k − r f_k; body M_p (ẍ, ÿ) = Σ f_k d_k, I_p ψ̈ = L_r Σ f_k. The torques'
    generalised force is u = (Σ τ_k d_k, L_r Σ τ_k)/r, hence
    u = (M_p (ẍ, ÿ) + (I_r/r) Σ ω̇_k d_k,  I_p ψ̈ + (I_r L_r/r) Σ ω̇_k),
    with ω̇_k by central differences along q(t) = q + v t + a t²/2.
    """
    r, L, Ir = p.wheel_radius, p.wheel_distance, p.wheel_inertia

    def directions(psi):
        return [np.array([math.cos(psi + 2 * math.pi * k / 3), math.sin(psi + 2 * math.pi * k / 3)]) for k in range(3)]

    def spins(t):
        qt, vt = q + v * t + 0.5 * a * t * t, v + a * t
        return np.array([(d @ vt[:2] + L * vt[2]) / r for d in directions(qt[2])])

    omega_dot = (spins(h) - spins(-h)) / (2 * h)
    planar = p.mass * a[:2] + (Ir / r) * sum(w * d for w, d in zip(omega_dot, directions(q[2])))
    yaw = p.body_inertia * a[2] + (Ir * L / r) * omega_dot.sum()
    return np.array([planar[0], planar[1], yaw])


@given(vec3, vec3, vec3)
def test_omni_regressor_gives_the_newton_euler_force(q, v, a):
    robot = OmniRobot()
    expected = omni_force_newton_euler(robot.parameters, q, v, a)
    assert np.allclose(robot.regressor(q, v, v, a) @ robot.theta, expected, rtol=1e-7, atol=1e-6)
    rows = np.array(robot.regressor_rows(q.tolist(), v.tolist(), v.tolist(), a.tolist()))
    assert np.allclose(rows @ robot.theta, expected, rtol=1e-7, atol=1e-6)
    split = robot.mass_regressor(q, a) + robot.coriolis_regressor(q, v, v) + robot.gravity_regressor(q)
    assert np.allclose(split @ robot.theta, expected, rtol=1e-7, atol=1e-6)


@given(vec3, vec3, vec3)
def test_omni_plant_accelerates_as_newton_euler_says(q, v, a):
    robot = OmniRobot()
    u = omni_force_newton_euler(robot.parameters, q, v, a)
    assert np.allclose(robot.acceleration(q, v, u), a, rtol=1e-7, atol=1e-6)


def test_omni_regressor_at_a_point_computed_by_hand():
    """θ = [m1, m3, a] = [18.055467449260476, 1.2116695391103427, 8.205467449260476]
    (test_paper_parameters_give_paper_theta).
    At ψ̇ = 2, w = (0.5, −0.25, 2), q̈ = (1, 2, −0.5):
    Y θ = (m1·1 + a·2·(−0.25), m1·2 − a·2·0.5, m3·(−0.5))
        = (18.055467449260476 − 4.102733724630238, 36.11093489852095 − 8.205467449260476, −0.6058347695551714)."""
    robot = OmniRobot()
    q, v = np.array([0.3, -1.0, 0.7]), np.array([0.1, 0.2, 2.0])
    w, acc = np.array([0.5, -0.25, 2.0]), np.array([1.0, 2.0, -0.5])
    expected = [13.952733724630238, 27.905467449260476, -0.6058347695551714]
    assert robot.regressor(q, v, w, acc) @ robot.theta == pytest.approx(expected, rel=1e-12)


def test_paper_parameters_give_paper_theta():
    """r² = 0.03965² = 0.0015721225; a = 3I_r/(2r²) = 0.0258/0.003144245 = 8.205467449;
    m1 = M_p + a = 9.85 + 8.205467449 = 18.055467449;
    m3 = I_p + 3I_r L_r²/r² = 0.522 + 0.001084245/0.0015721225 = 0.522 + 0.689669539 = 1.211669539."""
    assert OmniRobot().theta == pytest.approx([18.055467449, 1.211669539, 8.205467449], rel=1e-9)


@given(vec3, vec3)
def test_omni_mass_rate_minus_twice_coriolis_is_skew_symmetric(q, v):
    robot = OmniRobot()
    h = 1e-6
    m_dot = (robot.mass(q + h * v) - robot.mass(q - h * v)) / (2 * h)
    assert np.allclose(robot.mass_rate(q, v), m_dot, atol=1e-9)
    S = m_dot - 2 * robot.coriolis(q, v)
    assert np.allclose(S, -S.T, atol=1e-9)


# ----- the two-link arm: the Lagrangian -----------------------------------------------------------
STEP = 1e-20      # complex-step derivative: f′(x)·h = Im f(x + ih), exact to rounding for analytic f


def arm_centres(p, q):
    """The links' centres of mass in the plane (joint 1 from the horizontal, joint 2 relative to
    link 1); numpy, so that q may be complex (complex-step derivatives)."""
    link1 = np.array([np.cos(q[0]), np.sin(q[0])])
    link2 = np.array([np.cos(q[0] + q[1]), np.sin(q[0] + q[1])])
    return p.com1 * link1, p.length1 * link1 + p.com2 * link2


def arm_kinetic_energy(p, q, v):
    """T = ½ m1 |ċ1|² + ½ I1 q̇1² + ½ m2 |ċ2|² + ½ I2 (q̇1 + q̇2)², ċ = Im c(q + i·STEP·q̇)/STEP."""
    c1_dot, c2_dot = (c.imag / STEP for c in arm_centres(p, q + 1j * STEP * v))
    return 0.5 * (p.mass1 * c1_dot @ c1_dot + p.inertia1 * v[0] ** 2
                  + p.mass2 * c2_dot @ c2_dot + p.inertia2 * (v[0] + v[1]) ** 2)


def arm_potential_energy(p, q):
    c1, c2 = arm_centres(p, q)
    return p.gravity * (p.mass1 * c1[1] + p.mass2 * c2[1])


def arm_mass(p, q):
    """M from T, which is quadratic in q̇: M_ii = 2T(e_i), M_ij = T(e_i + e_j) − T(e_i) − T(e_j)."""
    e = np.eye(2)
    t = [arm_kinetic_energy(p, q, e[i]) for i in range(2)]
    off = arm_kinetic_energy(p, q, e[0] + e[1]) - t[0] - t[1]
    return np.array([[2 * t[0], off], [off, 2 * t[1]]])


def arm_lagrangian_terms(p, q, v, h=1e-4):
    """M(q); C(q, q̇) from the Christoffel symbols of M (∂M/∂q_i by central differences);
    g(q) = ∇P (complex step)."""
    dM = [(arm_mass(p, q + h * e) - arm_mass(p, q - h * e)) / (2 * h) for e in np.eye(2)]   # dM[i] = ∂M/∂q_i
    C = np.zeros((2, 2))
    for k in range(2):
        for j in range(2):
            C[k, j] = sum(0.5 * (dM[i][k, j] + dM[j][k, i] - dM[k][i, j]) * v[i] for i in range(2))
    g = np.array([arm_potential_energy(p, q + 1j * STEP * e).imag / STEP for e in np.eye(2)])
    return arm_mass(p, q), C, g


@given(vec2, vec2, vec2, vec2)
def test_arm_regressor_equals_the_lagrangian_model(q, v, w, a):
    arm = PlanarArm()
    M, C, g = arm_lagrangian_terms(arm.parameters, q, v)
    assert np.allclose(arm.regressor(q, v, w, a) @ arm.theta, M @ a + C @ w + g, rtol=1e-7, atol=1e-7)
    assert np.allclose(arm.mass(q), M, rtol=0.0, atol=1e-12)


@given(vec2, vec2)
def test_arm_mass_rate_is_the_derivative_of_the_lagrangian_mass(q, v):
    arm = PlanarArm()
    h = 1e-4
    numeric = (arm_mass(arm.parameters, q + h * v) - arm_mass(arm.parameters, q - h * v)) / (2 * h)
    assert np.allclose(arm.mass_rate(q, v), numeric, rtol=0.0, atol=1e-7)


@given(vec2, vec2)
def test_arm_mass_rate_minus_twice_coriolis_is_skew_symmetric(q, v):
    arm = PlanarArm()
    h = 1e-6
    m_dot = (arm.mass(q + h * v) - arm.mass(q - h * v)) / (2 * h)
    S = m_dot - 2 * arm.coriolis(q, v)
    assert np.allclose(S, -S.T, atol=1e-6)


# ----- energy and power ------------------------------------------------------------------------------
def _rk4(f, x, dt, steps):
    for _ in range(steps):
        k1 = f(x)
        k2 = f(x + dt / 2 * k1)
        k3 = f(x + dt / 2 * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


@pytest.mark.parametrize("model", [OmniRobot(), PlanarArm()], ids=["omni3", "arm2"])
def test_unforced_motion_conserves_energy(model):
    """With u = 0, ½ q̇ᵀMq̇ + P(q) is constant: Coriolis forces do no work (P from the links' heights)."""
    n = model.n

    def energy(x):
        q, v = x[:n], x[n:]
        potential = arm_potential_energy(model.parameters, q) if isinstance(model, PlanarArm) else 0.0
        return 0.5 * v @ model.mass(q) @ v + potential

    def f(x):
        q, v = x[:n], x[n:]
        return np.concatenate([v, model.acceleration(q, v, np.zeros(n))])

    x0 = np.concatenate([np.full(n, 0.3), np.array([0.4, -0.3, 2.0][:n])])
    x1 = _rk4(f, x0, 1e-3, 3000)
    assert energy(x1) == pytest.approx(energy(x0), rel=1e-7)


@given(vec3, vec3, vec3)
def test_wheel_map_balances_power(q, v, u):
    """uᵀq̇ = τᵀω with τ = B⁻¹u and ω = Bᵀq̇."""
    robot = OmniRobot()
    tau = robot.wheel_torques(q, u)
    omega = robot.wheel_speeds(q, v)
    assert u @ v == pytest.approx(tau @ omega, abs=1e-8)
    assert np.allclose(robot.body_velocity_from_wheels(q, omega), v)
