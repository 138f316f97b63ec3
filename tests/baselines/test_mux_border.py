"""The mux's border monitor: Definition 2 with b0, b1, b2 — standing still is never near the border.

Oracle: Definition 2 by hand at the top face y ≤ 4 of the paper's convex set (row x = y − 4,
ẋ = ẏ; b0 = 0.025, b1 = 0.3, b2 = 0.6, f_b(x) = 1/(x + b) − 1/b), the other faces far away.
"""
import numpy as np
import pytest

from sharedctl.baselines.comparison import build_strategy
from sharedctl.baselines.mux import HOLD, OPERATOR
from sharedctl.shared_controller import OperatorInput
from sharedctl.services.scenario_files import load
from sharedctl.transform import Desired


def _operator(force) -> OperatorInput:
    zero = np.zeros(3)
    return OperatorInput(Desired(zero, zero, zero), np.array(force, float), 1.0)


@pytest.fixture(scope="module")
def mux():
    loop, _, _ = load("paper_convex").closed_loop()
    assert (loop.sharing.bands.b0, loop.sharing.bands.b1, loop.sharing.bands.b2) == (0.025, 0.3, 0.6)
    return build_strategy("mux", loop)


@pytest.mark.parametrize("y, y_dot, near", [
    (3.9, 0.0, False),     # at rest 0.1 m from the face (inside the shared law's standoff band): safe
    (3.99, 0.0, False),    # at rest within b0: no approach, safe
    (3.5, 1.0, False),     # x = −0.5: f_b2 = 1/0.1 − 1/0.6 = 8.33 ≥ 1
    (3.8, 1.0, True),      # x = −0.2: f_b2 = 1/0.4 − 1/0.6 = 0.833 < 1
    (3.99, 0.001, True),   # x = −0.01: f_b2 = 0.028 ≥ 0.001, but any approach within b0 is hazardous
    (3.8, -1.0, False),    # moving away
    (4.1, 0.0, True),      # outside the set
])
def test_the_border_is_definition_2_without_a_standoff(mux, y, y_dot, near):
    assert mux.near_border(np.array([0.0, y, 0.0]), np.array([0.0, y_dot, 0.0])) is near


def test_the_operator_keeps_control_at_rest_near_a_face(mux):
    q, v = np.array([-0.9, 3.0, 0.0]), np.zeros(3)          # paper-convex's start: 0.1 m from x = −1
    operator = _operator([1.0, 0.0, 0.0])
    _, command = mux.step(mux.initial_state(q, v), q, v, operator, 0.002)
    assert command.mode == OPERATOR and command.operator_in_control
    assert np.array_equal(command.u, operator.force)


def test_an_approach_too_fast_for_the_band_is_held(mux):
    q, v = np.array([0.0, 3.8, 0.0]), np.array([0.0, 1.0, 0.0])
    _, command = mux.step(mux.initial_state(q, v), q, v, _operator([0.0, 5.0, 0.0]), 0.002)
    assert command.mode == HOLD and not command.operator_in_control
