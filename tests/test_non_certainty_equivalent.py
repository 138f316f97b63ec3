"""The NCE configuration (docs/control.md §4.2).

The paper's printed (13)–(15): its I&I identities hold when the input is exactly (13), a barrier
term breaks its error dynamics by γ_n W_nᵀ M⁻¹ u_{b,n}, and alone it crosses a face from speed —
kept as the documentation of why the configuration runs another law.

The configuration's law, (12) with a composite update on (14)–(15)'s filters
(CompositeAdaptiveLaw): the filtered identity M s = W_n θ + u_n for any applied input, the
Lyapunov decrease with its predicted rate, better estimation than (12), invariance from speed
(continuous and sampled at 500 Hz in shared mode), and that the configuration is no longer (12)
under sharing."""
import json
import math

import numpy as np
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.controllers import Adaptation, CompositeAdaptiveLaw, NonCertaintyEquivalentLaw
from sharedctl.human import FunctionTrajectory
from sharedctl.models import OmniRobot, PlanarArm
from sharedctl.reference import ReferenceShape
from sharedctl.services import cli
from sharedctl.services.scenario_files import load
from sharedctl.shared_controller import OperatorInput, SharedController
from sharedctl.sharing import Authority, Mode
from sharedctl.simulator import MachineController, make_controller, simulate
from sharedctl.transform import Desired, coordinates, reference_velocity_acceleration, z_dot

from .helpers import HALF_PI, WALL_K, WALL_T, line, omni_loop, packaged_run

BOX_K = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
BOX_T = [-3, -3, -3, -3, -HALF_PI, -HALF_PI]
ARM_K, ARM_T = [[1, 0], [0, -1]], [-1.2, -0.3]       # q1 ≤ 1.2, q2 ≥ −0.3


def exciting_wish():
    """A circle in (x, y) with a yaw wiggle: excites m1, m3 and the Coriolis parameter a."""
    def f(t):
        w, r, wy = 0.8, 1.0, 1.3
        q = [r * math.cos(w * t), r * math.sin(w * t), 0.6 * math.sin(wy * t)]
        qd = [-r * w * math.sin(w * t), r * w * math.cos(w * t), 0.6 * wy * math.cos(wy * t)]
        qdd = [-r * w * w * math.cos(w * t), -r * w * w * math.sin(w * t), -0.6 * wy * wy * math.sin(wy * t)]
        return q, qd, qdd
    return FunctionTrajectory(f)


def rk4(f, x, t, dt):
    d1 = f(t, x)
    d2 = f(t + dt / 2, x + dt / 2 * d1)
    d3 = f(t + dt / 2, x + dt / 2 * d2)
    d4 = f(t + dt, x + dt * d3)
    return x + dt / 6 * (d1 + 2 * d2 + 2 * d3 + d4)


def p_of(group, c, v, lam):
    """p = v − v_ref (11), from transform's numpy form (the laws compute on floats)."""
    v_ref, _ = reference_velocity_acceleration(group, c, z_dot(c, group.K @ v), lam)
    return v - v_ref


# ----- the printed law (13)–(15) -------------------------------------------------------------------
def _printed_law_on_the_wall():
    """The robot, the wall's group, the printed law (13), the reference shape and a slow line wish."""
    group = FeasibleSet.from_regions([Polytope.from_rows(WALL_K, WALL_T)]).groups[0]
    return OmniRobot(), group, NonCertaintyEquivalentLaw(), ReferenceShape(), line([-0.4, 2.5, 0.0], [0.05, 0.1, 0.05])


def test_printed_law_identities_hold_when_the_input_is_exactly_13():
    """M(ṗ_n + k_q p_n) = W_n θ + u_n and u_n = −W_n(θ̂ + β), with u̇_n = −α_n u_n + u_f (17)."""
    model, group, law, shape, wish = _printed_law_on_the_wall()
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
        q, th, s, u_n = x[:n], x[2 * n:2 * n + k], x[2 * n + k:-n], x[-n:]
        p_n, W_n = s[:n], s[n:].reshape(n, k)
        beta = law.gamma_n * W_n.T @ p_n
        lhs = model.mass(q) @ (out.state_dot[:n] + law.k_q * p_n)
        worst_filter = max(worst_filter, np.max(np.abs(lhs - (W_n @ model.theta + u_n))))
        worst_u = max(worst_u, np.max(np.abs(u_n + W_n @ (th + beta))))
        d2, _ = f(t + dt / 2, x + dt / 2 * d1)
        d3, _ = f(t + dt / 2, x + dt / 2 * d2)
        d4, _ = f(t + dt, x + dt * d3)
        x = x + dt / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
    assert worst_filter < 1e-6
    assert worst_u < 1e-6


def _printed_run_with_barrier(steps=4000, dt=5e-4):
    """(13) plus u_b = −Kᵀ Z1 z on the omnidirectional robot moving into the face y = 4, integrated here by
    RK4 with the filter u̇_{b,n} = −α_n u_{b,n} + u_b; returns the samples [q, q̇, θ̂, p_n, W_n, u_{b,n}]."""
    model, group, law, shape, wish = _printed_law_on_the_wall()
    n, k = model.n, model.n_theta
    q, v = np.array([-0.6, 3.7, 0.1]), np.array([0.2, 0.8, 0.0])        # 0.3 m from y = 4, moving into it
    c = coordinates(group, q, v, wish.sample(0.0), shape)
    x = np.concatenate([q, v, np.zeros(k), law.initial_state(model, group, c, q, v, np.zeros(k)), np.zeros(n)])
    m = 2 * n + k + n + n * k                 # start of u_{b,n}

    def f(t, x):
        q, v, th, s = x[:n], x[n:2 * n], x[2 * n:2 * n + k], x[2 * n + k:m]
        c = coordinates(group, q, v, wish.sample(t), shape)
        out = law.evaluate(model, group, c, q, v, th, s)
        u_b = -group.K.T @ (c.z / c.x)
        return np.concatenate([v, model.acceleration(q, v, out.u + u_b), out.theta_dot, out.state_dot,
                               -law.alpha_n * x[m:] + u_b])

    samples = []
    for step in range(steps):
        samples.append(x.copy())
        x = rk4(f, x, step * dt, dt)
    return model, law, np.array(samples), (n, k, m), dt


def test_a_barrier_term_adds_gamma_n_Wn_M_inverse_ubn_to_the_printed_error_dynamics():
    """θ̃ = θ̂ + β − θ obeys θ̃̇ = −γ_n W_nᵀM⁻¹W_n θ̃ only when u is exactly (13); with u = (13) + u_b it obeys
    θ̃̇ = −γ_n W_nᵀM⁻¹W_n θ̃ + γ_n W_nᵀM⁻¹u_{b,n}. θ̃̇ is measured by central differences of the solution."""
    model, law, X, (n, k, m), dt = _printed_run_with_barrier()
    g = law.gamma_n
    W_n = X[:, 3 * n + k:m].reshape(-1, n, k)
    estimate = X[:, 2 * n:2 * n + k] + g * np.einsum("tij,ti->tj", W_n, X[:, 2 * n + k:3 * n + k])
    measured = (estimate[2:] - estimate[:-2]) / (2 * dt)
    worst_full = worst_paper = largest = extra_largest = 0.0
    for i in range(1, len(X) - 1, 20):
        x = X[i]
        M_inv = np.linalg.inv(model.mass(x[:n]))
        theta_tilde = estimate[i] - model.theta
        paper = -g * W_n[i].T @ M_inv @ W_n[i] @ theta_tilde
        extra = g * W_n[i].T @ M_inv @ x[m:]
        worst_full = max(worst_full, np.max(np.abs(measured[i - 1] - (paper + extra))))
        worst_paper = max(worst_paper, np.max(np.abs(measured[i - 1] - paper)))
        largest = max(largest, np.max(np.abs(measured[i - 1])))
        extra_largest = max(extra_largest, np.max(np.abs(extra)))
    assert worst_full < 1e-4 * largest
    assert extra_largest > 0.05 * largest          # the barrier's term is not negligible …
    assert worst_paper > 0.05 * largest            # … so the paper's error dynamics no longer hold


def test_printed_law_estimate_error_never_grows_under_its_own_input():
    """With u exactly (13), |θ̃| is non-increasing and goes down under persistent excitation (the paper's claim)."""
    law = NonCertaintyEquivalentLaw()
    loop = omni_loop(BOX_K, BOX_T, exciting_wish(), "ce")
    loop.controller = MachineController(law, law)
    trace = simulate(loop, np.array([1.0, 0.0, 0.0]), np.zeros(3), 15.0, 1e-3)
    assert trace.finite and trace.inside.all()
    assert np.all(trace.set_class != 2)   # never hazardous
    err = np.linalg.norm(trace.theta_hat - loop.model.theta, axis=1)
    assert np.all(np.diff(err) <= 1e-9 * err[0])
    assert err[-1] < 0.1 * err[0]


@pytest.mark.parametrize("gamma_n,speed", [(0.5, 4.0), (0.5, 12.0)])
def test_printed_law_alone_crosses_the_border_when_started_towards_it(gamma_n, speed):
    """The safety gap (READING.md): (13) has no barrier term; started at speed it leaves the set."""
    law = NonCertaintyEquivalentLaw(gamma_n=gamma_n)
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 3.0, 0.0], [0.0, 0.0, 0.0]), "ce")
    loop.controller = MachineController(law, law)
    trace = simulate(loop, np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0]), 2.0, 5e-4)
    assert not trace.inside[-1]
    assert trace.margin[-1] <= 0.0


# ----- the configuration's law: (12) with the composite update ------------------------------------------
def test_the_nce_configuration_runs_the_composite_law_in_both_roles():
    controller = make_controller("nce")
    assert isinstance(controller.tracking, CompositeAdaptiveLaw)
    assert controller.hazard is controller.tracking


CASES = {
    "omni3": (OmniRobot(), WALL_K, WALL_T, np.array([-0.6, 2.0, 0.1]), np.array([0.2, -0.1, 0.3]),
              line([-0.4, 2.5, 0.0], [0.05, 0.1, 0.05])),
    "arm2": (PlanarArm(), ARM_K, ARM_T, np.array([0.2, 0.8]), np.array([0.3, -0.2]), line([0.4, 0.9], [0.05, 0.1])),
}

#: θ̂(0) − θ = 0.05 of these, per parameter (generous bounds of each model's θ, independent of its boxes)
INITIAL_ERROR_SCALE = {"omni3": (200.0, 50.0, 100.0), "arm2": (20.0, 10.0, 10.0, 200.0, 100.0)}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_filtered_identity_holds_for_an_arbitrary_applied_input(case):
    """M(q) s = W_n θ + u_n, s = p + (k_q − α_n) p_n, along a solution driven by an input that is not the
    law's — random sinusoids, gravity and a damped spring to the start that keeps the state in the group —
    fed to the law's filters through with_applied_input; the plant is model.acceleration, integrated here
    by RK4. The arm has Ṁ ≠ 0 and gravity."""
    model, K, T, q, v, wish = CASES[case]
    group = FeasibleSet.from_regions([Polytope.from_rows(K, T)]).groups[0]
    law, shape, n, k = CompositeAdaptiveLaw(), ReferenceShape(), model.n, model.n_theta
    rng = np.random.default_rng(3)
    inertia, start = np.diag(model.mass(q)), q.copy()
    amp, freq, phase = rng.uniform(1.0, 3.0, (3, n)), rng.uniform(0.3, 3.0, (3, n)), rng.uniform(0, 6, (3, n))

    def applied(t, q, v):
        wander = np.sum(amp * np.sin(freq * t + phase), axis=0) - 9.0 * (q - start) - 6.0 * v
        return inertia * wander + model.gravity(q)

    theta_hat = 0.5 * model.theta
    c = coordinates(group, q, v, wish.sample(0.0), shape)
    x = np.concatenate([q, v, law.initial_state(model, group, c, q, v, theta_hat)])

    def f(t, x):
        q, v, s = x[:n], x[n:2 * n], x[2 * n:]
        c = coordinates(group, q, v, wish.sample(t), shape)
        assert c.inside
        u = applied(t, q, v)
        rate = law.with_applied_input(law.evaluate(model, group, c, q, v, theta_hat, s).state_dot, u)
        return np.concatenate([v, model.acceleration(q, v, u), rate])

    dt, worst, largest = 1e-3, 0.0, 0.0
    for step in range(3000):
        t = step * dt
        q, v, s = x[:n], x[n:2 * n], x[2 * n:]
        c = coordinates(group, q, v, wish.sample(t), shape)
        p_n, W_n, u_n = s[:n], s[n:n + n * k].reshape(n, k), s[n + n * k:]
        ms = model.mass(q) @ (p_of(group, c, v, law.lam) + (law.k_q - law.alpha_n) * p_n)
        worst = max(worst, np.max(np.abs(ms - (W_n @ model.theta + u_n))))
        largest = max(largest, np.max(np.abs(u_n)))
        x = rk4(f, x, t, dt)
    assert largest > 0.1                    # the input filter is not idle
    assert worst < 1e-7 * max(largest, 1.0)


def _composite_machine_run(model, K, T, q, v, wish, theta_hat, duration, dt, law=None):
    """The composite law alone (u = u_f, no projection), integrated here by RK4; returns per-sample
    (L, L̇ predicted, its prediction-error part, margin)."""
    group = FeasibleSet.from_regions([Polytope.from_rows(K, T)]).groups[0]
    law, shape, n, k = law or CompositeAdaptiveLaw(), ReferenceShape(), model.n, model.n_theta
    c = coordinates(group, q, v, wish.sample(0.0), shape)
    x = np.concatenate([q, v, theta_hat, law.initial_state(model, group, c, q, v, theta_hat)])

    def f(t, x):
        q, v, th, s = x[:n], x[n:2 * n], x[2 * n:2 * n + k], x[2 * n + k:]
        c = coordinates(group, q, v, wish.sample(t), shape)
        assert c.inside
        out = law.evaluate(model, group, c, q, v, th, s)
        rate = law.with_applied_input(out.state_dot, out.u)
        return np.concatenate([v, model.acceleration(q, v, out.u), out.theta_dot, rate])

    L, Ldot, prediction, margin = [], [], [], []
    kp = np.broadcast_to(np.asarray(law.Kp, float), (n,))
    for step in range(int(round(duration / dt))):
        t = step * dt
        q, v, th, s = x[:n], x[n:2 * n], x[2 * n:2 * n + k], x[2 * n + k:]
        c = coordinates(group, q, v, wish.sample(t), shape)
        p = p_of(group, c, v, law.lam)
        err = th - model.theta
        L.append(0.5 * (c.z @ c.z + p @ model.mass(q) @ p + law.gamma_theta * err @ err))
        s_vec = p + (law.k_q - law.alpha_n) * s[:n]
        Phi = model.mass_regressor(q, s_vec) - s[n:n + n * k].reshape(n, k)
        e = Phi @ err
        pred = law.gamma_theta * law.gamma_n * (e @ e) / (1.0 + law.nu * np.sum(Phi**2))
        Ldot.append((law.lam + 1.0) * np.sum(c.z**2 / c.x) - p @ (kp * p) - pred)
        prediction.append(pred)
        margin.append(-np.max(c.x))
        x = rk4(f, x, t, dt)
    return np.array(L), np.array(Ldot), np.array(prediction), np.array(margin)


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_composite_lyapunov_function_never_increases_and_matches_its_predicted_rate(case):
    """L = ½(zᵀz + pᵀMp + γ_θ|θ̃|²): L̇ = (λ_q+1)zᵀZ1z − pᵀK_p p − γ_θγ_n|Φθ̃|²/(1 + ν|Φ|²), started moving
    towards a face (the continuous law without the projection and the leakage of §11, which can only
    decrease L further)."""
    model, K, T, q, v, wish = CASES[case]
    law = CompositeAdaptiveLaw(**model.default_gains.get("ce", {}), **model.default_gains.get("nce", {}),
                               adaptation=Adaptation(leakage=0.0))
    dt = 1e-3
    theta_hat0 = model.theta + 0.05 * np.array(INITIAL_ERROR_SCALE[case])
    L, Ldot, prediction, _ = _composite_machine_run(model, K, T, q, 3 * v, wish, theta_hat0, 4.0, dt, law)
    assert np.all(np.diff(L) <= 1e-9 * L[0])
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (Ldot[1:] + Ldot[:-1]) * dt)])
    assert np.max(np.abs((L - L[0]) - integral)) < 1e-4 * L[0]
    drop = np.sum(0.5 * (prediction[1:] + prediction[:-1]) * dt)
    assert drop > 0.2 * (L[0] - L[-1])        # the prediction term takes a good part of the decrease


@pytest.mark.parametrize("speed", [1.0, 4.0, 8.0, 12.0])
def test_composite_law_alone_keeps_the_group_with_the_margin_of_its_lyapunov_function(speed):
    """Started at speed towards the face y = 4 (machine only): every row stays ε·e^{−√(2L(0))} inside (§4.1)."""
    model = OmniRobot()
    q0, v0 = np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0])
    L, _, _, margin = _composite_machine_run(model, WALL_K, WALL_T, q0, v0, line([-0.5, 3.0, 0.0], [0.0, 0.0, 0.0]),
                                             0.5 * model.theta, 1.5, 5e-4)
    assert margin.min() > 0.0
    assert margin.min() >= ReferenceShape().epsilon * np.exp(-np.sqrt(2 * L[0]))


def test_composite_estimate_ends_well_below_the_certainty_equivalent_one_on_the_same_run():
    """Machine-only, 15 s of a circle-and-yaw wish from θ̂(0) = 0 (|θ̃(0)| = 19.9): (12) ends at |θ̃| ≈ 14,
    the composite law at ≈ 0.23 (Remark 3's better estimation, with a proof)."""
    errs = {}
    for kind in ("ce", "nce"):
        loop = omni_loop(BOX_K, BOX_T, exciting_wish(), kind)
        trace = simulate(loop, np.array([1.0, 0.0, 0.0]), np.zeros(3), 15.0, 1e-3)
        assert trace.finite and trace.inside.all()
        errs[kind] = np.linalg.norm(trace.theta_hat[-1] - loop.model.theta)
    initial = np.linalg.norm(loop.model.theta)
    assert errs["ce"] > 0.5 * initial
    assert errs["nce"] < 0.02 * initial
    assert errs["nce"] < 0.05 * errs["ce"]


def _sim_summary(controller, tmp_path):
    out = tmp_path / f"{controller}.json"
    assert cli.main(["sim", "paper_convex", "--controller", controller, "--json", str(out)]) == 0
    return json.loads(out.read_text())


def test_nce_and_ce_sim_summaries_differ_under_sharing(tmp_path):
    """`sharedctl sim paper_convex --controller nce --json` and `--controller ce`: different estimates."""
    nce, ce = _sim_summary("nce", tmp_path), _sim_summary("ce", tmp_path)
    assert nce["violations"] == ce["violations"] == 0
    assert np.linalg.norm(np.subtract(nce["theta_hat"], ce["theta_hat"])) > 0.1
    assert nce["tracking_rmse"] != ce["tracking_rmse"]


def test_nce_and_ce_machine_forces_differ_under_sharing():
    """The paper's convex scenario: same samples until the machine first acts, then different u_f."""
    (ce, _), (nce, _) = packaged_run("paper_convex", "ce"), packaged_run("paper_convex", "nce")   # machine from 9.81 s
    engaged = np.flatnonzero(ce.authority != int(Authority.HUMAN))
    assert engaged.size
    first = engaged[0]
    np.testing.assert_array_equal(nce.u_s[:first + 1], ce.u_s[:first + 1])
    both = (ce.authority != int(Authority.HUMAN)) & (nce.authority != int(Authority.HUMAN))
    assert np.max(np.abs(nce.u_f[both] - ce.u_f[both])) > 1.0


def _plant_rk4(model, q, v, u, period, substeps):
    h = period / substeps
    for _ in range(substeps):
        def f(y):
            return np.concatenate([y[3:], model.acceleration(y[:3], y[3:], u)])
        y = np.concatenate([q, v])
        d1 = f(y)
        d2 = f(y + h / 2 * d1)
        d3 = f(y + h / 2 * d2)
        d4 = f(y + h * d3)
        y = y + h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
        q, v = y[:3], y[3:]
    return q, v


@pytest.mark.parametrize("speed", [1.0, 3.0, 8.0])
def test_sampled_shared_step_keeps_the_set_from_speed(speed):
    """SharedController.step at 500 Hz in shared mode, the plant integrated between samples (RK4, 0.2 ms),
    started 0.5 m from the face y = 4 moving into it at 1, 3, 8 m/s while the operator's wish keeps going
    through it: every sample inside, θ̂ finite and in the box, and the machine did the work."""
    period = 0.002
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 3.5, 0.0], [0.0, 0.3, 0.0]), "nce", mode=Mode.SHARED)
    model = loop.model
    ctrl = SharedController(model, loop.feasible, loop.controller, loop.sharing, loop.reference)
    state = ctrl.initial_state(np.array([-0.5, 3.5, 0.0]))
    q, v = np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0])
    authorities, margins = [], []
    for k in range(int(2.0 / period)):
        t = k * period
        cmd = loop.human.command(t, q, v)
        state, out = ctrl.step(state, q, v, OperatorInput(loop.human.desired(t), cmd.force, cmd.intent), period)
        authorities.append(out.authority)
        margins.append(loop.feasible.margin(q))
        assert np.all(np.isfinite(out.theta_estimate))
        assert np.all(out.theta_estimate >= model.theta_lower) and np.all(out.theta_estimate <= model.theta_upper)
        q, v = _plant_rk4(model, q, v, out.u_s, period, 10)
    assert min(margins) > 0.0
    assert Authority.MACHINE in authorities
    assert state.theta_hat[0] > 0.0                          # the estimate moved under machine authority


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_the_composite_law_on_floats_is_its_formula(case):
    """evaluate and with_applied_input against the formulas written with numpy at one instant."""
    model, K, T, q, v, _ = CASES[case]
    group = FeasibleSet.from_regions([Polytope.from_rows(K, T)]).groups[0]
    n, k = model.n, model.n_theta
    wish = Desired(np.array([-0.4, 2.2, 0.3])[:n], np.array([-0.3, 1.2, 0.4])[:n], np.array([0.1, -0.2, -0.4])[:n])
    c = coordinates(group, q, v, wish, ReferenceShape())
    law = CompositeAdaptiveLaw(Kp=[30.0, 40.0, 50.0][:n], lam=1.3, gamma_theta=0.7, k_q=1.5, alpha_n=4.0,
                               gamma_n=20.0, nu=0.5)
    rng = np.random.default_rng(11)
    p_n, W_n, u_n = rng.standard_normal(n), rng.standard_normal((n, k)), rng.standard_normal(n)
    theta_hat, u_s = 0.5 * model.theta, rng.standard_normal(n)
    v_ref, a_ref = reference_velocity_acceleration(group, c, z_dot(c, group.K @ v), law.lam)
    p = v - v_ref
    Y = model.regressor(q, v, v_ref, a_ref)
    s = p + (law.k_q - law.alpha_n) * p_n
    W = (model.mass_rate_regressor(q, v, s) + law.k_q * model.mass_regressor(q, p)
         - model.coriolis_regressor(q, v, p) - Y)
    Phi = model.mass_regressor(q, s) - W_n
    out = law.evaluate(model, group, c, q, v, theta_hat, np.concatenate([p_n, W_n.ravel(), u_n]))
    np.testing.assert_allclose(out.u, -np.array(law.Kp) * p - group.K.T @ (c.z / c.x) + Y @ theta_hat, rtol=1e-12)
    normalised = law.gamma_n / (1 + law.nu * np.sum(Phi**2))
    update = -(Y.T @ p) / law.gamma_theta - normalised * Phi.T @ (Phi @ theta_hat - u_n)
    np.testing.assert_allclose(out.theta_dot, update, rtol=1e-12)
    rate = law.with_applied_input(out.state_dot, u_s)
    want = np.concatenate([-law.alpha_n * p_n + p, (-law.alpha_n * W_n + W).ravel(), -law.alpha_n * u_n + u_s])
    np.testing.assert_allclose(rate, want, rtol=1e-12, atol=1e-12)



def test_a_take_over_outside_the_remembered_group_recovers_and_restarts_the_filters_inside():
    """Sampled with delay, the machine can take over while q is outside the group it remembers: no law has a
    value there (z = ln(x/x_r) needs x < 0), so the recovery force acts — finite, pushing back across the face —
    with the law disengaged, and the first sample back inside starts the NCE filters from (15)."""
    loop, q0, _ = load("adversarial_wall").closed_loop("nce")
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference)
    state, dt, n = ctrl.initial_state(q0), 0.002, loop.model.n
    wish = Desired(np.array([0.0, 5.0, 0.0]), np.zeros(3), np.zeros(3))
    push, rest = OperatorInput(wish, np.array([0.0, 60.0, 0.0]), 1.0), OperatorInput(wish, np.zeros(3), 0.0)
    state, out = ctrl.step(state, np.array([0.0, 3.98, 0.0]), np.array([0.0, 1.0, 0.0]), push, dt)
    assert out.authority is not Authority.HUMAN                       # the machine takes the face's group
    for _ in range(200):                                              # safe, at rest: authority returns
        state, out = ctrl.step(state, np.array([0.0, 3.5, 0.0]), np.zeros(3), rest, dt)
    assert out.authority is Authority.HUMAN
    state, out = ctrl.step(state, np.array([0.0, 4.01, 0.0]), np.array([0.0, 0.5, 0.0]), push, dt)
    assert out.authority is not Authority.HUMAN and out.group is not None
    assert np.all(np.isfinite(out.u_s)) and out.u_f[1] < 0.0          # recovery: pushed back across y = 4
    assert state.law_role is None                                     # no law state outside
    state, out = ctrl.step(state, np.array([0.0, 3.97, 0.0]), np.array([0.0, -0.2, 0.0]), push, dt)
    assert state.law_role is not None and np.all(np.isfinite(state.law_state))
    assert np.allclose(state.law_state[-n:], dt * out.u_s)            # u_n from u_n(0) = 0: u̇_n = −α_n u_n + u_s
