"""The CBF filter's QP: its output satisfies the barrier condition at every step, and is u_h when it can be."""
import numpy as np
import pytest

from sharedctl.baselines.cbf import CbfSafetyFilter
from sharedctl.baselines.comparison import build_strategy

from .conftest import adversarial_run


@pytest.mark.parametrize("name,condition", [("adversarial_wall", "ideal"), ("adversarial_wall", "impaired"),
                                            ("adversarial_corner", "ideal")])
def test_the_barrier_condition_holds_at_every_step(name, condition):
    loop, trace = adversarial_run("cbf", condition, name, full=name == "adversarial_corner")
    cbf = build_strategy("cbf", loop)
    worst, active = -np.inf, 0
    for q, v, u, region in zip(trace.q, trace.v, trace.u, trace.mode):
        con = cbf.constraints(int(region), q, v)
        # ḧ_j + k1 ḣ_j + k0 h_j ≥ 0 under the nominal model, for every face of the polytope filtered against
        slack = con.A @ u - con.b
        worst = max(worst, float(np.max(slack / (1.0 + np.abs(con.b)))))
        active += int(np.any(np.abs(slack) <= 1e-9 * (1.0 + np.abs(con.b))))
    assert worst <= 1e-9
    assert active > 100                                    # the constraint was binding, not idle
    assert np.nanmax(trace.residual) <= 1e-9 * (1.0 + np.abs(trace.u).max())


def test_the_filter_passes_the_operator_unchanged_when_no_constraint_binds():
    loop, trace = adversarial_run("cbf")
    passed = trace.operator_in_control
    assert passed[:100].all()                              # far from the face at the start
    assert np.array_equal(trace.u[passed], trace.u_h[passed])


def test_the_qp_is_the_projection_onto_the_constraint():
    """One face, u_h pushing through it: the solution is u_h minus its excess along the face's row."""
    A = np.array([[0.0, 1.0, 0.0]])
    b = np.array([2.0])
    u = CbfSafetyFilter.solve(np.array([3.0, 7.0, -1.0]), A, b)
    assert np.allclose(u, [3.0, 2.0, -1.0])


def test_contradicting_faces_are_softened_not_raised():
    A = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    b = np.array([-1.0, -1.0])                             # u_y ≤ −1 and u_y ≥ 1: infeasible
    u = CbfSafetyFilter.solve(np.zeros(3), A, b)
    assert np.all(np.isfinite(u))
    assert abs(u[1]) < 1e-6                                # the slack splits the violation evenly


def test_in_the_corner_the_filter_switches_to_the_polytope_it_can_stay_in():
    """Starts in {y ≤ 0} (more margin), slides along y = 0 under the undamped operator and back; at
    x = −6 cm, {x ≤ 0} has 5 cm more margin and is admissible, so the filter switches (at 5.7 s)."""
    loop, trace = adversarial_run("cbf", "ideal", "adversarial_corner", full=True)
    assert trace.inside.all()
    switches = np.flatnonzero(np.diff(trace.mode) != 0)
    assert switches.size >= 1
    for k in switches + 1:                                 # after every switch q lies in the new polytope
        assert loop.feasible.regions[trace.mode[k]].contains(trace.q[k])
