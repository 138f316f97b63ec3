"""Output-feedback law (25)–(29) with the velocity observer (40): no velocity in the loop."""
import numpy as np
import pytest

from sharedctl.controllers import VelocityObserver

from .helpers import PAPER_CONVEX_K, PAPER_CONVEX_T, WALL_K, WALL_T, line, omni_loop
from sharedctl.simulator import simulate


def test_law_never_reads_the_true_velocity():
    """Feeding the law a wrong velocity changes only the adaptation, never u_f: (25) uses q alone."""
    from sharedctl.constraints import FeasibleSet, Polytope
    from sharedctl.controllers import OutputFeedbackLaw
    from sharedctl.models import OmniRobot
    from sharedctl.reference import ReferenceShape
    from sharedctl.transform import coordinates

    model, law, shape = OmniRobot(), OutputFeedbackLaw(), ReferenceShape()
    group = FeasibleSet.from_regions([Polytope.from_rows(WALL_K, WALL_T)]).groups[0]
    q = np.array([-0.4, 3.2, 0.1])
    wish = line([-0.5, 3.0, 0.0], [0.1, 0.2, 0.0]).sample(0.3)
    outputs = []
    for v in (np.zeros(3), np.array([5.0, -3.0, 1.0])):
        c = coordinates(group, q, v, wish, shape)
        state = law.initial_state(model, group, c, q, v, np.zeros(3))
        outputs.append(law.evaluate(model, group, c, q, v, np.ones(3), state))
    assert np.array_equal(outputs[0].u, outputs[1].u)
    assert not np.array_equal(outputs[0].theta_dot, outputs[1].theta_dot)


def test_tracks_the_wish_inside_with_the_observers_estimate():
    loop = omni_loop(WALL_K, WALL_T, line([-0.2, 1.5, 0.0], [0.05, 0.1, 0.0]), "of")
    trace = simulate(loop, np.array([-0.5, 1.0, 0.0]), np.zeros(3), 10.0, 1e-3)
    assert trace.finite and trace.inside.all()
    err = np.linalg.norm(trace.q - trace.q_d, axis=1)
    assert err[0] > 0.5 and err[-1] < 0.005


def test_observer_error_goes_to_zero():
    loop = omni_loop(WALL_K, WALL_T, line([-0.2, 1.5, 0.0], [0.05, 0.1, 0.0]), "of")
    trace = simulate(loop, np.array([-0.5, 1.0, 0.0]), np.array([0.4, -0.3, 0.2]), 6.0, 1e-3)
    err = np.linalg.norm(trace.v_hat - trace.v, axis=1)
    assert err[0] > 0.4                      # the observer starts from v̂(0) = 0
    assert np.max(err[trace.t > 2.0]) < 2e-3  # then converges (to within the smooth sign's width)
    assert err[-1] < 1e-3


def test_observer_alone_recovers_a_known_velocity():
    """(40) on a signal with bounded q̈: s = q̃̇ + q̃ and q̃ go to zero (43)."""
    obs = VelocityObserver()
    dt, x = 1e-4, obs.initial_state(np.zeros(3))
    errs = []

    def tq(tt):
        return np.array([np.sin(tt), 0.5 * np.cos(2 * tt), 0.2 * tt])

    for k in range(40000):
        t = k * dt
        q = np.array([np.sin(t), 0.5 * np.cos(2 * t), 0.2 * t])
        v = np.array([np.cos(t), -np.sin(2 * t), 0.2])
        errs.append(np.linalg.norm(obs.velocity(q, x) - v))
        k1 = obs.derivative(q, x)
        k2 = obs.derivative(tq(t + dt / 2), x + dt / 2 * k1)
        k3 = obs.derivative(tq(t + dt / 2), x + dt / 2 * k2)
        k4 = obs.derivative(tq(t + dt), x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    errs = np.array(errs)
    assert errs[0] > 0.9
    assert errs[-10000:].max() < 2e-3


@pytest.mark.parametrize("speed", [1.0, 3.0, 6.0])
def test_group_stays_feasible_when_started_at_speed_towards_the_wall(speed):
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 3.0, 0.0], [0.0, 0.0, 0.0]), "of")
    trace = simulate(loop, np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0]), 2.0, 5e-4)
    assert trace.finite and trace.inside.all()


def test_converges_to_the_projection_when_the_wish_leaves():
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 3.0, 0.0], [0.0, 0.4, 0.0]), "of")
    trace = simulate(loop, np.array([-0.5, 3.0, 0.0]), np.zeros(3), 12.0, 1e-3)
    assert trace.inside.all()
    assert trace.q_r[-1, 1] == pytest.approx(4.0 - loop.reference.epsilon, abs=1e-6)
    assert np.linalg.norm(trace.q[-1] - trace.q_r[-1]) < 0.01


def _pure_output_feedback():
    from sharedctl.controllers import OutputFeedbackLaw
    from sharedctl.simulator import MachineController

    of = OutputFeedbackLaw()
    return MachineController(of, of, VelocityObserver())


@pytest.mark.parametrize("speed", [1.0, 3.0])
def test_printed_law_alone_keeps_the_group_feasible_in_continuous_time(speed):
    loop = omni_loop(WALL_K, WALL_T, line([-0.5, 3.0, 0.0], [0.0, 0.0, 0.0]), "of")
    loop.controller = _pure_output_feedback()
    trace = simulate(loop, np.array([-0.5, 3.5, 0.0]), np.array([0.0, speed, 0.0]), 2.0, 5e-4)
    assert trace.finite and trace.inside.all()


def test_printed_law_alone_sampled_at_500_hz_escapes_near_a_face():
    """Why the barrier law on v̂ runs in the hazardous set: near a face the filtered-derivative terms
    of (25) scale like k_o (k2+1)/x², and a 2 ms hold makes the loop unstable (docs/control.md §4.3);
    the configuration, with OutputFeedbackBarrierLaw in the hazard role, stays inside, and that law
    is what acts."""
    from sharedctl.controllers import OutputFeedbackBarrierLaw
    from sharedctl.sampled import simulate_sampled

    from sharedctl.sharing import Authority, LawRole, Mode
    from sharedctl.simulator import make_controller

    # the paper's convex scenario: the operator creeps into the face x = −1 and the machine
    # takes over 5 mm from it (at t ≈ 10.1 s), and the law flings the robot out
    wish = line([-0.5, 2.0, 0.0], [-0.05, 0.15, 0.0])
    loop = omni_loop(PAPER_CONVEX_K, PAPER_CONVEX_T, wish, "of", mode=Mode.SHARED)
    loop.controller = _pure_output_feedback()
    trace = simulate_sampled(loop, np.array([-0.9, 3.0, 0.0]), np.zeros(3), 14.0, 0.002)
    assert not trace.inside.all()
    loop.controller = make_controller("of")
    assert isinstance(loop.controller.hazard, OutputFeedbackBarrierLaw)
    trace = simulate_sampled(loop, np.array([-0.9, 3.0, 0.0]), np.zeros(3), 14.0, 0.002)
    assert trace.inside.all()
    acting = (trace.authority != int(Authority.HUMAN)) & (trace.role == int(LawRole.HAZARD))
    assert acting.any()
