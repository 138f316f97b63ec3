"""The transformed error dynamics (9)–(11), checked against finite differences on real motion."""
import math

import numpy as np
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.models import OmniRobot, PlanarArm
from sharedctl.reference import ReferenceShape
from sharedctl.transform import Desired, coordinates, reference_acceleration, reference_velocity, z_dot

from .helpers import WALL_K, WALL_T

SHAPE = ReferenceShape()
LAM = 1.3


def desired(t, n):
    """A smooth wish that leaves the set (so the reference bends) and wiggles."""
    base = np.array([-0.5 - 0.3 * t, 2.0 + 1.2 * t, 0.4 * math.sin(t)])[:n]
    vel = np.array([-0.3, 1.2, 0.4 * math.cos(t)])[:n]
    acc = np.array([0.0, 0.0, -0.4 * math.sin(t)])[:n]
    return Desired(base, vel, acc)


def forcing(t, n):
    if n == 2:   # the arm: roughly gravity-compensating, plus a wiggle
        return np.array([6.0 + math.sin(2 * t), 1.5 + 0.5 * math.cos(t)])
    return np.array([3 * math.sin(2 * t), 40 * math.cos(t), 0.5 * math.sin(3 * t)])


def trajectory(model, q0, v0, dt=1e-4, steps=20000):
    n = model.n
    x = np.concatenate([q0, v0])

    def f(t, x):
        return np.concatenate([x[n:], model.acceleration(x[:n], x[n:], forcing(t, n))])

    xs = [x]
    for k in range(steps):
        t = k * dt
        k1 = f(t, x)
        k2 = f(t + dt / 2, x + dt / 2 * k1)
        k3 = f(t + dt / 2, x + dt / 2 * k2)
        k4 = f(t + dt, x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        xs.append(x)
    return np.array(xs)


CASES = {
    "omni3": (OmniRobot(), WALL_K, WALL_T, np.array([-0.9, 2.5, 0.1]), np.array([0.1, 0.5, 0.2])),
    "arm2": (PlanarArm(), [[1, 0], [0, -1]], [-1.2, -0.3], np.array([0.2, 0.5]), np.array([0.3, -0.2])),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_error_dynamics_match_finite_differences(case):
    model, K, T, q0, v0 = CASES[case]
    n = model.n
    group = FeasibleSet.from_regions([Polytope.from_rows(K, T)]).groups[0]
    dt = 1e-4
    xs = trajectory(model, q0, v0, dt, 6000)
    checked = 0
    for k in range(100, 5900, 500):
        t = k * dt

        def at(j):
            q, v = xs[j, :n], xs[j, n:]
            c = coordinates(group, q, v, desired(j * dt, n), SHAPE)
            return q, v, c, v - reference_velocity(group, c, LAM)

        q, v, c, p = at(k)
        assert c.inside
        _, _, c_plus, p_plus = at(k + 1)
        _, _, c_minus, p_minus = at(k - 1)
        zd = z_dot(c, group.K @ v)
        # (9): ż from the formula equals the numerical derivative of z = ln(x/x_r)
        assert np.allclose((c_plus.z - c_minus.z) / (2 * dt), zd, rtol=1e-4, atol=1e-5)
        # (11), first line: ż = Z1 K p + (λ+1) Z1 z with Z1 = diag(1/x)
        assert np.allclose(zd, (group.K @ p) / c.x + (LAM + 1) * c.z / c.x, atol=1e-9)
        # (11), second line: M ṗ + C p + Y θ = u
        a_ref = reference_acceleration(group, c, zd, LAM)
        v_ref = v - p
        p_dot = (p_plus - p_minus) / (2 * dt)
        Y = model.regressor(q, v, v_ref, a_ref)
        lhs = model.mass(q) @ p_dot + model.coriolis(q, v) @ p + Y @ model.theta
        assert np.allclose(lhs, forcing(t, n), rtol=1e-4, atol=1e-4)
        checked += 1
    assert checked >= 10


def test_projected_reference_lies_inside_the_group():
    group = FeasibleSet.from_regions([Polytope.from_rows(WALL_K, WALL_T)]).groups[0]
    wish = Desired(np.array([-3.0, 9.0, 4.0]), np.zeros(3), np.zeros(3))   # far outside on every row
    c = coordinates(group, np.array([-0.5, 3.0, 0.0]), np.zeros(3), wish, SHAPE)
    assert np.all(group.K @ c.q_r + group.T <= -SHAPE.epsilon + 1e-12)
    assert np.allclose(group.K @ c.q_r + group.T, c.x_r)
