"""The intent measure (45), v_h = ½ Σ_j k_p,j q̂_h,j² (`sharedctl.human.intent`), against values computed by hand."""
import numpy as np
import pytest

from sharedctl.human import intent

KP = (20.0, 20.0, 5.0)
DEFLECTION = (0.5, -0.25, 0.1)
HAND = 3.15          # ½(20·0.25 + 20·0.0625 + 5·0.01) = ½(5 + 1.25 + 0.05)


def test_intent_on_python_floats_is_the_spring_energy():
    assert intent(KP, DEFLECTION) == pytest.approx(HAND, rel=1e-15)


def test_intent_on_numpy_vectors_is_the_spring_energy():
    value = intent(np.array(KP), np.array(DEFLECTION))
    assert type(value) is float and value == pytest.approx(HAND, rel=1e-15)


def test_intent_of_a_batch_is_one_spring_energy_per_robot():
    """Deflections (n, N), one robot per column; the second robot's handle is at (1, 0, −1): ½(20 + 5)."""
    deflections = np.array([DEFLECTION, (1.0, 0.0, -1.0)]).T
    np.testing.assert_allclose(intent(np.array(KP)[:, None], deflections), [HAND, 12.5], rtol=1e-15)


def test_a_centred_handle_has_no_intent():
    assert intent(KP, (0.0, 0.0, 0.0)) == 0.0
