"""The output-feedback configuration's barrier law on the observer's v̂ (docs/control.md §4.3).

Run as a script, prints the observer's largest error during machine interventions (the ṽ_max that
docs/control.md §4.3 states), per run, and the sized rest margin d*(ṽ) against the one measured
with ṽ held:

    .venv/bin/python -m tests.test_output_feedback_barrier
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sharedctl.controllers import Adaptation, OutputFeedbackBarrierLaw
from sharedctl.controllers.output_feedback_barrier import KAPPA
from sharedctl.metrics import summarize
from sharedctl.sampled import simulate_sampled
from sharedctl.sharing import Authority, LawRole, Mode
from sharedctl.simulator import MachineController, simulate
from sharedctl.transform import bounded_reference_signals, coordinates

from .helpers import PAPER_CONVEX_K, PAPER_CONVEX_T, WALL_K, WALL_T, line, omni_loop, packaged_run


PERIOD = 0.002                        # the daemon's 500 Hz
SCENARIOS = ("paper_convex", "paper_nonconvex", "adversarial_wall")
SPEEDS = (1.0, 3.0, 6.0, 8.0)
#: the stated bound on |v − v̂| during machine interventions (docs/control.md §4.3): the packaged
#: scenarios stay below V_TILDE_SCENARIOS, fast approaches up to 8 m/s below V_TILDE_MAX
V_TILDE_SCENARIOS = 0.7
V_TILDE_MAX = 3.0


# ----- the reference velocity and the Lyapunov identity ------------------------------------
def _wall_barrier_loop(wish, mode=Mode.MACHINE, projection=False):
    """The barrier law alone in both roles, on the true velocity (no observer); without `projection`,
    the law as derived (neither the projection nor the leakage of docs/control.md §11)."""
    loop = omni_loop(WALL_K, WALL_T, wish, "of", mode=mode)
    law = OutputFeedbackBarrierLaw() if projection else OutputFeedbackBarrierLaw(adaptation=Adaptation(leakage=0.0))
    law.projects_estimate = projection
    loop.controller = MachineController(law, law)
    return loop, law


def test_a_row_is_caught_by_the_bound_z_tanh_z_at_least_abs_z_minus_kappa():
    z = np.linspace(-40.0, 40.0, 400001)
    slack = z * np.tanh(z) - (np.abs(z) - KAPPA)
    assert slack.min() >= 0.0
    assert slack.min() < 1e-4          # KAPPA is the tightest such constant (to its rounding)


def test_reference_rate_matches_finite_differences_of_the_reference_velocity():
    """v̇_ref of transform.bounded_reference_signals against central differences of v_ref along a
    trajectory that nears the face y = 4 and a wish that moves and accelerates."""
    loop, law = _wall_barrier_loop(line([-0.5, 3.0, 0.0], [-0.1, 0.3, 0.2]))
    dt = 1e-4
    trace = simulate(loop, np.array([-0.4, 3.7, 0.1]), np.array([0.2, 0.9, -0.3]), 0.4, dt)
    assert trace.inside.all()
    group = loop.feasible.groups[0]
    f = group.floats
    v_ref, a_ref = [], []
    for k in range(trace.t.size):
        c = coordinates(group, trace.q[k], trace.v[k], loop.human.desired(trace.t[k]), loop.reference)
        _, _, vr, ar = bounded_reference_signals(c.floats, f.K, f.K_inv, trace.v[k].tolist(), law.lam)
        v_ref.append(vr)
        a_ref.append(ar)
    v_ref, a_ref = np.array(v_ref), np.array(a_ref)
    differences = (v_ref[2:] - v_ref[:-2]) / (2 * dt)
    scale = np.abs(a_ref).max()
    assert scale > 0.3
    assert np.max(np.abs(differences - a_ref[1:-1])) < 1e-3 * scale


def _lyapunov_along(loop, law, trace, v_used=None):
    group = loop.feasible.groups[0]
    L, Ldot, residual = [], [], []
    for k in range(trace.t.size):
        q, v = trace.q[k], trace.v[k]
        c = coordinates(group, q, v, loop.human.desired(trace.t[k]), loop.reference)
        L.append(law.lyapunov(loop.model, group, c, q, v, trace.theta_hat[k]))
        Ldot.append(law.lyapunov_rate(loop.model, group, c, q, v))
        if v_used is not None:
            residual.append(law.lyapunov_residual(loop.model, group, c, q, v, v_used[k], trace.theta_hat[k]))
    return np.array(L), np.array(Ldot), np.array(residual)


def test_lyapunov_rate_is_minus_lambda_v_prime_tanh_z_minus_p_kp_p_on_the_true_velocity():
    """With v̂ = v: L(t) − L(0) = ∫(−λ Σ V′(z) tanh z − pᵀK_p p) dt along a solution driven from
    1 m/s towards the face with the true θ in the plant, and L never increases."""
    loop, law = _wall_barrier_loop(line([-0.5, 2.0, 0.0], [-0.1, 0.3, 0.05]))
    dt = 5e-4
    trace = simulate(loop, np.array([-0.5, 3.6, 0.2]), np.array([0.3, 1.0, 0.0]), 3.0, dt)
    assert trace.finite and trace.inside.all()
    L, Ldot, _ = _lyapunov_along(loop, law, trace)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (Ldot[1:] + Ldot[:-1]) * dt)])
    assert np.max(np.abs((L - L[0]) - integral)) < 1e-4 * L[0]
    assert np.all(np.diff(L) <= 1e-9 * L[0])
    assert L[0] - L[-1] > 10.0         # not vacuous: L moved (its θ̃ part need not)


# ----- a known observer error: the residual and the ISS bound ------------------------------
def _injected_error(t):
    return 0.3 * np.array([np.sin(7.0 * t), np.cos(5.0 * t), 0.5 * np.sin(3.0 * t)])


def _integrate_with_injected_error(loop, law, q0, v0, duration, dt):
    """RK4 of plant and θ̂ with the law fed v̂ = v − ṽ(t) (ṽ known), machine authority throughout."""
    model, group = loop.model, loop.feasible.groups[0]

    def rates(t, q, v, theta_hat):
        v_hat = v - _injected_error(t)
        c = coordinates(group, q, v_hat, loop.human.desired(t), loop.reference)
        out = law.evaluate(model, group, c, q, v_hat, theta_hat, law.initial_state(model, group, c, q, v, theta_hat))
        return v, model.acceleration(q, v, out.u), out.theta_dot

    q, v, theta_hat = np.asarray(q0, float), np.asarray(v0, float), np.zeros(model.n_theta)
    rows = []
    for k in range(int(round(duration / dt))):
        t = k * dt
        rows.append((t, q, v, theta_hat))
        state = (q, v, theta_hat)
        k1 = rates(t, *state)
        k2 = rates(t + dt / 2, *(s + dt / 2 * d for s, d in zip(state, k1)))
        k3 = rates(t + dt / 2, *(s + dt / 2 * d for s, d in zip(state, k2)))
        k4 = rates(t + dt, *(s + dt * d for s, d in zip(state, k3)))
        q, v, theta_hat = (s + dt / 6 * (a + 2 * b + 2 * c + d) for s, a, b, c, d in zip(state, k1, k2, k3, k4))
    t, q, v, theta_hat = (np.array(column) for column in zip(*rows))
    return t, q, v, theta_hat


def iss_constants(loop, law, t, q, v):
    """c₁, c₂ of docs/control.md §4.3 for the omnidirectional robot (m_Y = c_Y = 1, g_Y = 0), with
    ā₁, V_r, A₀ the largest values of |ẋ_r/x_r + μ + μ′|, |v_ref| and |v̇_ref(v = 0)| on the run."""
    group = loop.feasible.groups[0]
    f = group.floats
    a1, v_r, a0 = 0.0, 0.0, 0.0
    for k in range(t.size):
        c = coordinates(group, q[k], v[k], loop.human.desired(t[k]), loop.reference)
        tz = np.tanh(c.z)
        a1 = max(a1, np.max(np.abs(c.x_r_dot / c.x_r - law.lam * tz - law.lam * (1 - tz * tz))))
        _, _, v_ref, a_ref0 = bounded_reference_signals(c.floats, f.K, f.K_inv, [0.0] * 3, law.lam)
        v_r, a0 = max(v_r, np.linalg.norm(v_ref)), max(a0, np.linalg.norm(a_ref0))
    upper, lower = np.array(loop.model.theta_upper), np.array(loop.model.theta_lower)
    theta_bar = np.linalg.norm(np.maximum(np.abs(upper), np.abs(lower)))
    diameter = np.linalg.norm(upper - lower)
    cond_k = np.linalg.cond(np.array(f.K))
    kp = np.broadcast_to(np.asarray(law.Kp, float), (3,))
    h = cond_k * a1 + v_r
    b = kp.max() + (theta_bar + diameter) * h
    return b * b / (3 * kp.min()) + diameter * h, diameter * (h * v_r + a0)


def test_with_a_known_observer_error_the_lyapunov_rate_stays_within_the_iss_bound():
    """ṽ(t) injected (0.3 m/s): L(t) − L(0) equals the integral of the predicted
    −λ Σ V′(z) tanh z − pᵀK_p p plus the residual pᵀ[K_p ṽ + (Ŷ − Y)θ] + ṽᵀŶθ̃, and L̇ (central
    differences) stays below −λ(|z|₁ − κn) − ¼pᵀK_p p + c₁|ṽ|² + c₂|ṽ|."""
    loop, law = _wall_barrier_loop(line([-0.5, 3.9, 0.0], [0.0, 0.3, 0.0]))
    dt = 5e-4
    t, q, v, theta_hat = _integrate_with_injected_error(loop, law, [-0.5, 3.7, 0.1], [0.0, 1.0, 0.2], 2.0, dt)
    group = loop.feasible.groups[0]
    trace = type("Run", (), {"t": t, "q": q, "v": v, "theta_hat": theta_hat})
    v_tilde = np.array([_injected_error(tk) for tk in t])
    L, nominal, residual = _lyapunov_along(loop, law, trace, v_used=v - v_tilde)
    predicted = nominal + residual
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (predicted[1:] + predicted[:-1]) * dt)])
    residual_integral = np.sum(np.abs(residual)) * dt
    assert residual_integral > 10.0                                    # the observer error matters here …
    assert np.max(np.abs((L - L[0]) - integral)) < 1e-3 * residual_integral   # … exactly as derived
    measured = (L[2:] - L[:-2]) / (2 * dt)
    c1, c2 = iss_constants(loop, law, t, q, v)
    kp = np.broadcast_to(np.asarray(law.Kp, float), (3,))
    bound = []
    for k in range(1, t.size - 1):
        c = coordinates(group, q[k], v[k], loop.human.desired(t[k]), loop.reference)
        p, *_ = law.error_signals(loop.model, group, c, q[k], v[k])
        e = np.linalg.norm(v_tilde[k])
        bound.append(-law.lam * (np.abs(c.z).sum() - KAPPA * 3) - 0.25 * p @ (kp * p) + c1 * e * e + c2 * e)
    assert np.all(measured <= np.array(bound))


# ----- the configuration under the 500 Hz sampled controller -------------------------------
def _approach(speed, start=0.5, mode=Mode.SHARED):
    """`start` m from the face y = 4 of the paper's convex set, moving into it at `speed`, the
    operator's line continuing through the face at 0.3 m/s, the 500 Hz SharedController.step."""
    q0 = np.array([-0.5, 4.0 - start, 0.0])
    loop = omni_loop(PAPER_CONVEX_K, PAPER_CONVEX_T, line(q0, [0.0, 0.3, 0.0]), "of", mode=mode)
    return simulate_sampled(loop, q0, np.array([0.0, speed, 0.0]), 2.0, PERIOD)


@functools.lru_cache(maxsize=None)
def approach(speed):
    return _approach(speed)


@functools.lru_cache(maxsize=None)
def scenario_run(name):
    """The run `sharedctl sim <name> --controller of` makes, and its summary."""
    trace, dt = packaged_run(name, "of")
    return trace, summarize(trace, dt)


def intervening(trace):
    return (trace.authority == int(Authority.MACHINE)) | (trace.authority == int(Authority.SHARED))


def observer_error_during_interventions(trace) -> float:
    """max |v − v̂| over the samples with machine authority (0 when the machine never acted)."""
    machine = intervening(trace)
    return float(np.linalg.norm(trace.v - trace.v_hat, axis=1)[machine].max()) if machine.any() else 0.0


@pytest.mark.parametrize("speed", SPEEDS)
def test_fast_approach_is_stopped_by_the_barrier_law_at_500_hz(speed):
    trace = approach(speed)
    assert trace.finite and trace.inside.all()
    hazard = intervening(trace) & (trace.role == int(LawRole.HAZARD))
    assert hazard.any(), "the barrier law never ran: the case would test nothing"


@settings(max_examples=6, deadline=None, derandomize=True)
@given(start=st.floats(0.35, 0.8), speed=st.floats(0.5, 6.0), angle=st.floats(-0.6, 0.6))
def test_random_approach_towards_a_face_stays_inside_at_500_hz(start, speed, angle):
    q0 = np.array([-0.5, 4.0 - start, 0.0])
    v0 = speed * np.array([np.sin(angle), np.cos(angle), 0.0])
    loop = omni_loop(PAPER_CONVEX_K, PAPER_CONVEX_T, line(q0, 0.3 * v0 / speed), "of", mode=Mode.SHARED)
    trace = simulate_sampled(loop, q0, v0, 1.5, PERIOD)
    assert trace.finite and trace.inside.all()


@pytest.mark.parametrize("speed", SPEEDS)
def test_observer_error_during_a_fast_approach_stays_within_the_stated_bound(speed):
    trace = approach(speed)
    assert 0.0 < observer_error_during_interventions(trace) <= V_TILDE_MAX


@pytest.mark.parametrize("name", SCENARIOS)
def test_observer_error_during_the_packaged_scenarios_stays_within_the_stated_bound(name):
    trace, _ = scenario_run(name)
    assert 0.0 < observer_error_during_interventions(trace) <= V_TILDE_SCENARIOS


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_configuration_runs_its_own_laws_and_keeps_the_set(name):
    """`sharedctl sim <name> --controller of`: law_share ≥ 0.9 (the barrier law counts as the
    configuration's own), no violation, and the barrier law really ran."""
    trace, summary = scenario_run(name)
    assert summary["violations"] == 0 and summary["finite"]
    assert summary["law_share"] >= 0.9
    assert np.any(intervening(trace) & (trace.role == int(LawRole.HAZARD)))


# ----- the margin sized from ṽ_max: a persistent worst-direction observer error ------------
#: held observer errors (m/s) along the face's normal, towards the face: the stated bound on the
#: packaged scenarios, about twice it, and the stated bound on 8 m/s approaches
HELD_ERRORS = (V_TILDE_SCENARIOS, 1.5, V_TILDE_MAX)
SUBSTEPS = 8


def rest_margin(law, v_tilde, eps):
    """d* of docs/control.md §4.3: the distance at which, at rest on a unit-norm row with the
    reference at its closest (|x_r| = ε), the barrier's push (1+k_b) ln(ε/d)/d and the reference's
    K_p λ d tanh ln(ε/d) balance the damping's misread K_p ṽ. Root of a scalar equation (brentq),
    independent of the law's code."""
    from scipy.optimize import brentq

    kp = float(np.max(law.Kp))

    def imbalance(d):
        z = np.log(eps / d)
        return (1.0 + law.barrier_weight) * z / d + kp * law.lam * d * np.tanh(z) - kp * v_tilde

    return brentq(imbalance, 1e-9, eps)


def held_error_run(speed, v_tilde, duration=3.0):
    """The barrier law alone at 500 Hz (zero-order hold, RK4 with 8 substeps) on the wall group,
    fed v̂ = v − ṽ with ṽ = (0, v_tilde, 0) held: the law reads the approach v_tilde slower than it
    is. Start 0.5 m from the face y = 4 at `speed` towards it; the wish lies beyond the face, so
    the reference rests at ε. Returns the margins 4 − y after every period."""
    loop, law = _wall_barrier_loop(line([-0.5, 3.5, 0.0], [0.0, 0.3, 0.0]))
    model, group = loop.model, loop.feasible.groups[0]
    lower, upper = np.array(model.theta_lower), np.array(model.theta_upper)
    q, v, theta_hat = np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0]), np.zeros(model.n_theta)
    error, h = np.array([0.0, v_tilde, 0.0]), PERIOD / SUBSTEPS
    margins = []
    for k in range(int(round(duration / PERIOD))):
        v_hat = v - error
        c = coordinates(group, q, v_hat, loop.human.desired(k * PERIOD), loop.reference)
        state = law.initial_state(model, group, c, q, v_hat, theta_hat)
        out = law.evaluate(model, group, c, q, v_hat, theta_hat, state)
        theta_hat = np.clip(theta_hat + PERIOD * out.theta_dot, lower, upper)
        for _ in range(SUBSTEPS):
            k1 = (v, model.acceleration(q, v, out.u))
            k2 = (v + h / 2 * k1[1], model.acceleration(q + h / 2 * k1[0], v + h / 2 * k1[1], out.u))
            k3 = (v + h / 2 * k2[1], model.acceleration(q + h / 2 * k2[0], v + h / 2 * k2[1], out.u))
            k4 = (v + h * k3[1], model.acceleration(q + h * k3[0], v + h * k3[1], out.u))
            q = q + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        margins.append(4.0 - q[1])
    return np.array(margins), loop.reference.epsilon, law


@pytest.mark.parametrize("v_tilde", HELD_ERRORS[:2])
@pytest.mark.parametrize("speed", (1.0, 8.0))
def test_a_held_observer_error_leaves_the_robot_at_the_sized_rest_margin_and_never_closer(speed, v_tilde):
    """ṽ held at 0.7 and 1.5 m/s towards the face, approaches at 1 and 8 m/s: the robot comes to
    rest at d*(ṽ) (within 3 %) and at no period is it closer than 0.97 d*."""
    margins, eps, law = held_error_run(speed, v_tilde)
    d_star = rest_margin(law, v_tilde, eps)
    assert 0.0 < d_star < eps
    assert abs(margins[-1] - d_star) <= 0.03 * d_star
    assert margins.min() >= 0.97 * d_star


def test_a_held_error_at_the_approach_bound_undershoots_its_rest_margin_but_stays_inside():
    """ṽ = 3 m/s held (the bound measured on 8 m/s approaches, there only a transient): the robot
    overshoots d* on the way in — the static sizing does not cover the transient — yet stays inside
    and settles at d*."""
    margins, eps, law = held_error_run(8.0, HELD_ERRORS[2])
    d_star = rest_margin(law, HELD_ERRORS[2], eps)
    assert margins.min() > 0.0
    assert margins.min() < 0.9 * d_star                 # the transient is real: the sizing is static
    assert abs(margins[-1] - d_star) <= 0.03 * d_star


if __name__ == "__main__":
    for name in SCENARIOS:
        trace, summary = scenario_run(name)
        print(f"{name:18s} max |v - v_hat| during interventions {observer_error_during_interventions(trace):.3f} m/s"
              f"  law_share {summary['law_share']}  min_margin {summary['min_margin']:.4f} m")
    for speed in SPEEDS:
        trace = approach(speed)
        print(f"approach {speed:.0f} m/s     max |v - v_hat| during interventions "
              f"{observer_error_during_interventions(trace):.3f} m/s  min_margin {trace.margin.min():.4f} m")
    for v_tilde in HELD_ERRORS:
        margins, eps, law = held_error_run(8.0, v_tilde)
        print(f"held error {v_tilde:.1f} m/s    rest margin d* {rest_margin(law, v_tilde, eps) * 1e3:.1f} mm"
              f"  measured: closest {margins.min() * 1e3:.1f} mm, at rest {margins[-1] * 1e3:.1f} mm")
