"""Non-certainty-equivalent law (13)–(15): the identities its proof rests on, estimate
convergence under persistent excitation, and the safety gap with its remedy."""
import math

import numpy as np
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.controllers import NonCertaintyEquivalentLaw
from sharedctl.human import FunctionTrajectory
from sharedctl.models import OmniRobot
from sharedctl.reference import ReferenceShape
from sharedctl.simulator import MachineController, make_controller, simulate
from sharedctl.transform import coordinates

from .helpers import HALF_PI, WALL_K, WALL_T, line, omni_loop

BOX_K = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
BOX_T = [-3, -3, -3, -3, -HALF_PI, -HALF_PI]


def exciting_wish():
    """A circle in (x, y) with a yaw wiggle: excites m1, m3 and the Coriolis parameter a."""
    def f(t):
        w, r, wy = 0.8, 1.0, 1.3
        q = [r * math.cos(w * t), r * math.sin(w * t), 0.6 * math.sin(wy * t)]
        qd = [-r * w * math.sin(w * t), r * w * math.cos(w * t), 0.6 * wy * math.cos(wy * t)]
        qdd = [-r * w * w * math.cos(w * t), -r * w * w * math.sin(w * t), -0.6 * wy * wy * math.sin(wy * t)]
        return q, qd, qdd
    return FunctionTrajectory(f)


def test_filtered_identities_of_the_proof_hold_along_solutions():
    """M(ṗ_n + k_q p_n) = W_n θ + u_n and u_n = −W_n(θ̂ + β), with u̇_n = −α_n u_n + u_f (17)."""
    model = OmniRobot()
    group = FeasibleSet.from_regions([Polytope.from_rows(WALL_K, WALL_T)]).groups[0]
    law = NonCertaintyEquivalentLaw()
    shape = ReferenceShape()
    wish = line([-0.4, 2.5, 0.0], [0.05, 0.1, 0.05])
    n, k = model.n, model.n_theta
    q, v = np.array([-0.6, 2.0, 0.1]), np.array([0.2, -0.1, 0.0])
    c = coordinates(group, q, v, wish.sample(0.0), shape)
    theta_hat = np.zeros(k)
    state = law.initial_state(model, group, c, q, v, theta_hat)
    x = np.concatenate([q, v, theta_hat, state, np.zeros(n)])

    def f(t, x):
        q, v, th, s = x[:n], x[n:2 * n], x[2 * n:2 * n + k], x[2 * n + k:-n]
        u_n = x[-n:]
        c = coordinates(group, q, v, wish.sample(t), shape)
        out = law.evaluate(model, group, c, q, v, th, s)
        rates = [v, model.acceleration(q, v, out.u), out.theta_dot, out.state_dot, -law.alpha_n * u_n + out.u]
        return np.concatenate(rates), out

    dt, worst_filter, worst_u = 5e-4, 0.0, 0.0
    for step in range(6000):
        t = step * dt
        d1, out = f(t, x)
        q, v, th, s, u_n = x[:n], x[n:2 * n], x[2 * n:2 * n + k], x[2 * n + k:-n], x[-n:]
        p_n, W_n = s[:n], s[n:].reshape(n, k)
        beta = law.gamma_n * W_n.T @ p_n
        p_n_dot = out.state_dot[:n]
        lhs = model.mass(q) @ (p_n_dot + law.k_q * p_n)
        worst_filter = max(worst_filter, np.max(np.abs(lhs - (W_n @ model.theta + u_n))))
        worst_u = max(worst_u, np.max(np.abs(u_n + W_n @ (th + beta))))
        d2, _ = f(t + dt / 2, x + dt / 2 * d1)
        d3, _ = f(t + dt / 2, x + dt / 2 * d2)
        d4, _ = f(t + dt, x + dt * d3)
        x = x + dt / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
    assert worst_filter < 1e-6
    assert worst_u < 1e-6


def test_estimate_error_never_grows_and_shrinks_under_persistent_excitation():
    """θ̃ = θ̂ + β − θ obeys θ̃̇ = −γ_n W_nᵀ M⁻¹ W_n θ̃: |θ̃| is non-increasing, and goes down with PE."""
    loop = omni_loop(BOX_K, BOX_T, exciting_wish(), "nce")
    trace = simulate(loop, np.array([1.0, 0.0, 0.0]), np.zeros(3), 15.0, 1e-3)
    assert trace.finite and trace.inside.all()
    assert np.all(trace.role == 0)   # never hazardous: (13) ran the whole time
    err = np.linalg.norm(trace.theta_hat - loop.model.theta, axis=1)
    assert np.all(np.diff(err) <= 1e-9 * err[0])
    assert err[-1] < 0.1 * err[0]


def test_certainty_equivalent_estimate_does_not_converge_as_well_on_the_same_run():
    """The contrast the paper draws (Remark 3): same run, (12) learns θ less well than (13)."""
    errs = {}
    for kind in ("ce", "nce"):
        loop = omni_loop(BOX_K, BOX_T, exciting_wish(), kind)
        trace = simulate(loop, np.array([1.0, 0.0, 0.0]), np.zeros(3), 15.0, 1e-3)
        errs[kind] = np.linalg.norm(trace.theta_hat[-1] - loop.model.theta)
    assert errs["nce"] < errs["ce"]


def _towards_wall(controller, speed):
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 3.0, 0.0], [0.0, 0.0, 0.0]), "nce")
    loop.controller = controller
    return simulate(loop, np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0]), 2.0, 5e-4)


@pytest.mark.parametrize("gamma_n,speed", [(0.5, 4.0), (0.5, 12.0)])
def test_printed_law_alone_crosses_the_border_when_started_towards_it(gamma_n, speed):
    """The safety gap (READING.md): (13) has no barrier term; started at speed it leaves the set."""
    law = NonCertaintyEquivalentLaw(gamma_n=gamma_n)
    trace = _towards_wall(MachineController(law, law), speed)
    assert not trace.inside[-1]
    assert trace.margin[-1] <= 0.0


@pytest.mark.parametrize("gamma_n", [0.5, 50.0])
@pytest.mark.parametrize("speed", [1.0, 4.0, 8.0, 12.0])
def test_with_the_certainty_equivalent_law_in_the_hazardous_set_it_stays_inside(gamma_n, speed):
    controller = make_controller("nce", {"nce": {"gamma_n": gamma_n}})
    trace = _towards_wall(controller, speed)
    assert trace.finite and trace.inside.all()
    if speed >= 8.0:
        assert (trace.role == 1).any()   # the hazard law did the work
