"""The plant models: regressors against independent closed forms, passivity, energy."""
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sharedctl.models import OmniRobot, PlanarArm

finite = st.floats(-3.0, 3.0, allow_nan=False)
vec3 = st.lists(finite, min_size=3, max_size=3).map(np.array)
vec2 = st.lists(finite, min_size=2, max_size=2).map(np.array)


def arm_closed_form(p, q, v):
    """Textbook two-link arm, written out independently of the regressor."""
    m1, m2, l1, lc1, lc2, I1, I2, g0 = p.mass1, p.mass2, p.length1, p.com1, p.com2, p.inertia1, p.inertia2, p.gravity
    c2, s2 = math.cos(q[1]), math.sin(q[1])
    d11 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * c2) + I1 + I2
    d12 = m2 * (lc2**2 + l1 * lc2 * c2) + I2
    d22 = m2 * lc2**2 + I2
    M = np.array([[d11, d12], [d12, d22]])
    h = -m2 * l1 * lc2 * s2
    C = np.array([[h * v[1], h * (v[0] + v[1])], [-h * v[0], 0.0]])
    g = np.array(
        [(m1 * lc1 + m2 * l1) * g0 * math.cos(q[0]) + m2 * lc2 * g0 * math.cos(q[0] + q[1]),
         m2 * lc2 * g0 * math.cos(q[0] + q[1])]
    )
    return M, C, g


@given(vec3, vec3, vec3, vec3)
def test_omni_regressor_equals_paper_model(q, v, w, a):
    robot = OmniRobot()
    m1, m3, c = robot.theta
    M = np.diag([m1, m1, m3])
    C = c * v[2] * np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 0]])
    assert np.allclose(robot.regressor(q, v, w, a) @ robot.theta, M @ a + C @ w)


@given(vec2, vec2, vec2, vec2)
def test_arm_regressor_equals_textbook_model(q, v, w, a):
    arm = PlanarArm()
    M, C, g = arm_closed_form(arm.parameters, q, v)
    assert np.allclose(arm.regressor(q, v, w, a) @ arm.theta, M @ a + C @ w + g)


@given(vec2, vec2)
def test_arm_mass_rate_is_the_derivative_of_mass_and_skew_with_coriolis(q, v):
    arm = PlanarArm()
    h = 1e-6
    numeric = (arm.mass(q + h * v) - arm.mass(q - h * v)) / (2 * h)
    m_dot = arm.mass_rate(q, v)
    assert np.allclose(m_dot, numeric, atol=1e-6)
    S = m_dot - 2 * arm.coriolis(q, v)
    assert np.allclose(S, -S.T, atol=1e-9)


@given(vec3, vec3)
def test_omni_coriolis_is_skew_symmetric(q, v):
    C = OmniRobot().coriolis(q, v)
    assert np.allclose(C, -C.T)


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
    """With u = 0, ½ q̇ᵀMq̇ + P(q) is constant: Coriolis forces do no work."""
    n = model.n

    def energy(x):
        q, v = x[:n], x[n:]
        potential = 0.0
        if isinstance(model, PlanarArm):
            th = model.theta
            potential = th[3] * math.sin(q[0]) + th[4] * math.sin(q[0] + q[1])
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


def test_paper_parameters_give_paper_theta():
    m1, m3, a = OmniRobot().theta
    r, Ir = 0.03965, 0.0086
    assert m1 == pytest.approx(9.85 + 3 * Ir / (2 * r * r))
    assert m3 == pytest.approx(0.522 + 3 * Ir * 0.205**2 / (r * r))
    assert a == pytest.approx(3 * Ir / (2 * r * r))
