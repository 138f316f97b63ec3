"""Certainty-equivalent law (12): Lyapunov decrease, invariance at speed, tracking, projection."""
import numpy as np
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.controllers import Adaptation, CertaintyEquivalentLaw
from sharedctl.models import PlanarArm
from sharedctl.simulator import ClosedLoop, make_controller, simulate
from sharedctl.sharing import Mode, SharingParameters
from sharedctl.human import ScriptedOperator
from sharedctl.reference import ReferenceShape
from sharedctl.transform import coordinates

from .helpers import WALL_K, WALL_T, line, omni_loop

LAW = CertaintyEquivalentLaw()   # the defaults make_controller("ce") uses for the omnidirectional robot


def lyapunov_along(loop, trace, law=LAW):
    group = loop.feasible.groups[0]
    L, Ldot = [], []
    for k in range(trace.t.size):
        q, v = trace.q[k], trace.v[k]
        c = coordinates(group, q, v, loop.human.desired(trace.t[k]), loop.reference)
        L.append(law.lyapunov(loop.model, group, c, q, v, trace.theta_hat[k]))
        Ldot.append(law.lyapunov_rate(loop.model, group, c, q, v))
    return np.array(L), np.array(Ldot)


@pytest.mark.parametrize("projection", [False, True])
def test_lyapunov_function_never_increases_and_matches_its_predicted_rate(projection):
    """With the parameter projection and the leakage on, L may only drop further (the boxes contain θ),
    so the identity L(t) − L(0) = ∫L̇ becomes an inequality; without them ((12) as printed), it holds
    to integration accuracy."""
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 2.0, 0.0], [-0.1, 0.3, 0.05]), "ce")
    loop.controller.tracking.projects_estimate = projection
    if not projection:
        loop.controller.tracking.adaptation = Adaptation(leakage=0.0)
    dt = 1e-3
    trace = simulate(loop, np.array([-0.5, 3.0, 0.2]), np.array([0.3, 0.8, 0.0]), 6.0, dt)
    assert trace.finite and trace.inside.all()
    L, Ldot = lyapunov_along(loop, trace)
    assert np.all(np.diff(L) <= 1e-9 * L[0])
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (Ldot[1:] + Ldot[:-1]) * dt)])
    if projection:
        assert np.all((L - L[0]) - integral <= 1e-4 * L[0])
    else:
        assert np.max(np.abs((L - L[0]) - integral)) < 1e-4 * L[0]
    # the tracking part of L decays (θ̃ need not: no persistent excitation here)
    assert np.linalg.norm(trace.q[-1] - trace.q_r[-1]) < 0.05 * np.linalg.norm(trace.q[0] - trace.q_r[0])


@pytest.mark.parametrize("speed", [1.0, 3.0, 8.0])
def test_group_stays_feasible_when_started_at_speed_towards_the_wall(speed):
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 3.0, 0.0], [0.0, 0.5, 0.0]), "ce")
    trace = simulate(loop, np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0]), 3.0, 5e-4)
    assert trace.finite
    assert trace.inside.all()
    # the margin Theorem 1 implies: every row stays ε·exp(−√(2 L(0))) inside its face
    L0 = lyapunov_along(loop, trace)[0][0]
    assert trace.margin.min() >= loop.reference.epsilon * np.exp(-np.sqrt(2 * L0))


def test_tracks_the_wish_when_it_stays_well_inside():
    wish = line([-0.2, 1.5, 0.0], [0.05, 0.1, 0.0])   # stays ≥ 0.7 m from every face for 10 s
    loop = omni_loop(WALL_K, WALL_T, wish, "ce")
    trace = simulate(loop, np.array([-0.5, 1.0, 0.0]), np.zeros(3), 10.0, 2e-3)
    err = np.linalg.norm(trace.q - trace.q_d, axis=1)
    assert err[0] > 0.5
    assert err[-1] < 0.01
    # far inside, the projected reference is the wish itself
    assert np.allclose(trace.q_r[-1], trace.q_d[-1], atol=1e-6)


def test_converges_to_the_projection_when_the_wish_leaves():
    wish = line([-0.5, 3.0, 0.0], [0.0, 0.4, 0.0])     # crosses y = 4 at t = 2.5 s and keeps going
    loop = omni_loop(WALL_K, WALL_T, wish, "ce")
    trace = simulate(loop, np.array([-0.5, 3.0, 0.0]), np.zeros(3), 12.0, 2e-3)
    assert trace.inside.all()
    assert trace.q_d[-1, 1] > 7.0
    # the projection sits ε inside the face y = 4
    assert trace.q_r[-1, 1] == pytest.approx(4.0 - loop.reference.epsilon, abs=1e-6)
    assert np.linalg.norm(trace.q[-1] - trace.q_r[-1]) < 0.01


def test_estimate_stays_bounded():
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 2.0, 0.0], [-0.1, 0.3, 0.05]), "ce")
    trace = simulate(loop, np.array([-0.5, 3.0, 0.2]), np.array([0.3, 0.8, 0.0]), 6.0, 2e-3)
    # Theorem 1: γ|θ̃|² ≤ 2 L(0), so |θ̂| ≤ |θ| + sqrt(2 L(0)/γ)
    L0 = lyapunov_along(loop, trace)[0][0]
    bound = np.linalg.norm(loop.model.theta) + np.sqrt(2 * L0 / LAW.gamma_theta)
    assert np.max(np.linalg.norm(trace.theta_hat, axis=1)) <= bound


def test_arm_lyapunov_function_never_increases():
    """The same law on the 2-link arm (position-dependent M, gravity, Ṁ ≠ 0)."""
    arm = PlanarArm()
    feasible = FeasibleSet.from_regions([Polytope.from_rows([[1, 0], [0, -1]], [-1.2, -0.3])])
    wish = line([0.3, 0.8], [0.2, -0.15])
    loop = ClosedLoop(arm, feasible, ScriptedOperator(wish, np.full(2, 5.0), np.full(2, 2.0)),
                      make_controller("ce", model=arm), SharingParameters(mode=Mode.MACHINE), ReferenceShape())
    trace = simulate(loop, np.array([0.3, 0.8]), np.zeros(2), 6.0, 1e-3)
    assert trace.finite and trace.inside.all()
    L, _ = lyapunov_along(loop, trace, loop.controller.tracking)
    assert np.all(np.diff(L) <= 1e-9 * L[0])
