"""The projected reference (7): strictly inside, equal to the wish far inside, smooth."""
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sharedctl.reference import ReferenceShape, saturate

SHAPE = ReferenceShape(epsilon=0.05, gamma=40.0)


@given(st.floats(-1e6, 1e6, allow_nan=False))
def test_reference_is_strictly_below_minus_epsilon(m):
    x_r, d1, d2 = saturate(np.array([m]), SHAPE)
    assert x_r[0] <= -SHAPE.epsilon
    assert np.isfinite(x_r[0]) and 0.0 <= d1[0] <= 1.0 and d2[0] <= 0.0


def test_reference_equals_the_wish_far_inside():
    m = np.array([-0.5, -1.0, -3.0])
    x_r, d1, _ = saturate(m, SHAPE)
    assert np.allclose(x_r, m, atol=1e-7)
    assert np.allclose(d1, 1.0, atol=1e-7)


def test_reference_saturates_near_minus_epsilon_outside():
    x_r, d1, _ = saturate(np.array([0.0, 1.0, 100.0]), SHAPE)
    assert x_r[0] < -SHAPE.epsilon and np.all(x_r <= -SHAPE.epsilon)
    assert x_r[2] == pytest.approx(-SHAPE.epsilon, abs=1e-12)
    assert d1[2] == pytest.approx(0.0, abs=1e-12)


def test_derivatives_match_finite_differences():
    m = np.linspace(-0.6, 0.4, 201)
    h = 1e-5
    x_r, d1, d2 = saturate(m, SHAPE)
    xp, d1p, _ = saturate(m + h, SHAPE)
    xm, d1m, _ = saturate(m - h, SHAPE)
    assert np.allclose((xp - xm) / (2 * h), d1, atol=1e-6)
    assert np.allclose((d1p - d1m) / (2 * h), d2, atol=1e-4)
