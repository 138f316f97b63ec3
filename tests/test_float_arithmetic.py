"""The per-sample arithmetic on Python floats (short_vectors, the laws) equals the paper's formulas
written with numpy, for the omnidirectional robot (n = 3) and the planar arm (n = 2)."""
import numpy as np
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.controllers import Adaptation, CertaintyEquivalentLaw, NonCertaintyEquivalentLaw
from sharedctl.models import OmniRobot, PlanarArm
from sharedctl.reference import ReferenceShape, saturate, saturate_floats
from sharedctl.short_vectors import all_finite, dot, matvec, rows_of
from sharedctl.transform import Desired, coordinates, reference_velocity_acceleration, z_dot

from .helpers import WALL_K, WALL_T

RTOL = 1e-13


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_dot_and_matvec_equal_numpy(n):
    rng = np.random.default_rng(n)
    A, x = rng.standard_normal((4, n)), rng.standard_normal(n)
    assert dot(A[0].tolist(), x.tolist()) == pytest.approx(float(A[0] @ x), rel=RTOL)
    np.testing.assert_allclose(matvec(rows_of(A), x.tolist()), A @ x, rtol=RTOL)


def test_all_finite_rejects_nan_and_both_infinities():
    assert all_finite([0.0, -1e308, 5.0])
    assert not all_finite([0.0, float("nan")])
    assert not all_finite([float("inf"), 1.0])
    assert not all_finite([1.0, float("-inf")])


def test_saturate_on_floats_equals_the_vectorised_saturate():
    m = [-3.0, -0.2, -0.05, 0.0, 0.01, 0.3, 40.0, -40.0]
    for got, want in zip(saturate_floats(m, ReferenceShape()), saturate(np.array(m), ReferenceShape())):
        np.testing.assert_allclose(got, want, rtol=RTOL, atol=1e-300)


CASES = {
    "omni3": (OmniRobot(), WALL_K, WALL_T, np.array([-0.9, 2.5, 0.1]), np.array([0.1, 0.5, 0.2])),
    "arm2": (PlanarArm(), [[1, 0], [0, -1]], [-1.2, -0.3], np.array([0.2, 0.5]), np.array([0.3, -0.2])),
}


def _instant(case):
    model, K, T, q, v = CASES[case]
    feasible = FeasibleSet.from_regions([Polytope.from_rows(K, T)])
    n = model.n
    wish = Desired(np.array([-0.4, 2.2, 0.3])[:n], np.array([-0.3, 1.2, 0.4])[:n], np.array([0.1, -0.2, -0.4])[:n])
    group = feasible.groups[0]
    return model, group, coordinates(group, q, v, wish, ReferenceShape()), q, v


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_the_certainty_equivalent_law_on_floats_is_paper_12(case):
    model, group, c, q, v = _instant(case)
    law = CertaintyEquivalentLaw(Kp=[30.0, 40.0, 50.0][:model.n], lam=1.3, gamma_theta=0.7)
    theta_hat = 0.5 * model.theta
    zd = z_dot(c, group.K @ v)
    v_ref, a_ref = reference_velocity_acceleration(group, c, zd, law.lam)
    p = v - v_ref
    Y = model.regressor(q, v, v_ref, a_ref)
    out = law.evaluate(model, group, c, q, v, theta_hat, np.zeros(0))
    np.testing.assert_allclose(out.u, -np.array(law.Kp) * p - group.K.T @ (c.z / c.x) + Y @ theta_hat, rtol=RTOL)
    np.testing.assert_allclose(out.theta_dot, -(Y.T @ p) / law.gamma_theta, rtol=RTOL)


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_the_non_certainty_equivalent_law_on_floats_is_paper_13_14(case):
    """(13)–(14) with the robust update's leakage on the estimate ϑ = θ̂ + β (docs/control.md §11)."""
    model, group, c, q, v = _instant(case)
    band_lower, band_upper = 0.4 * model.theta, 0.6 * model.theta
    law = NonCertaintyEquivalentLaw(adaptation=Adaptation(leakage=2.0, band_lower=tuple(band_lower),
                                                          band_upper=tuple(band_upper)))
    n, k = model.n, model.n_theta
    rng = np.random.default_rng(7)
    p_n, W_n = rng.standard_normal(n), rng.standard_normal((n, k))
    theta_hat = 0.5 * model.theta
    zd = z_dot(c, group.K @ v)
    v_ref, a_ref = reference_velocity_acceleration(group, c, zd, law.lam)
    p = v - v_ref
    W = law.regressor_w(model, q, v, p, p_n, v_ref, a_ref)
    s = p + (law.k_q - law.alpha_n) * p_n
    g = law.gamma_n
    out = law.evaluate(model, group, c, q, v, theta_hat, np.concatenate([p_n, W_n.ravel()]))
    np.testing.assert_allclose(out.u, -W @ (theta_hat + g * W_n.T @ p_n) - g * W_n @ (W_n.T @ s), rtol=1e-12)
    estimate = theta_hat + g * W_n.T @ p_n
    leak = 2.0 * (estimate - np.clip(estimate, band_lower, band_upper))
    assert np.count_nonzero(leak) >= 2                      # the leakage acts on this estimate
    np.testing.assert_allclose(out.theta_dot, g * (law.alpha_n * W_n - W).T @ p_n + g * law.k_q * W_n.T @ p_n - leak,
                               rtol=1e-12)
    np.testing.assert_allclose(out.state_dot,
                               np.concatenate([-law.alpha_n * p_n + p, (-law.alpha_n * W_n + W).ravel()]), rtol=1e-12)
