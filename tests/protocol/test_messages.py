"""Message construction validates every field: what exists may be sent."""
from __future__ import annotations

import math

import numpy as np
import pytest

from protocol_samples import command, state
from sharedctl.protocol import messages as m
from sharedctl.protocol.errors import NonFiniteValue, OutOfRange, WrongLength
from sharedctl.protocol.wire_types import ROBOT_DIMS, Dims


def test_numpy_arrays_are_accepted_as_vectors():
    assert state(q=np.array([0.1, 0.2, 0.3])).q == (0.1, 0.2, 0.3)


def test_thirty_three_region_margins_are_wrong_length():
    with pytest.raises(WrongLength):
        state(region_margins=[0.0] * 33)


def test_nine_dof_is_wrong_length():
    with pytest.raises(WrongLength):
        m.GroundTruth(seq=0, time=0.0, q=[0.0] * 9, qd=[0.0] * 9)


def test_empty_pose_is_wrong_length():
    with pytest.raises(WrongLength):
        m.GroundTruth(seq=0, time=0.0, q=[], qd=[])


def test_text_of_257_characters_is_wrong_length():
    with pytest.raises(WrongLength):
        m.Event(seq=0, time=0.0, kind="info", severity="info", source="ctl", text="x" * 257)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_building_a_message_with_a_non_finite_float_is_refused(bad):
    with pytest.raises(NonFiniteValue):
        m.Heartbeat(role="a", id="b", seq=0, time=bad)


def test_integer_too_large_for_a_float_is_out_of_range():
    with pytest.raises(OutOfRange):
        m.Heartbeat(role="a", id="b", seq=0, time=10**400)


@pytest.mark.parametrize("changes", [
    {"joystick": (1.5, 0.0, 0.0)}, {"send_time": -1.0}, {"seq": -1}, {"seq": 2**64},
    {"control_request": "grab"}, {"operator_id": "al/ice"}, {"operator_id": ""}, {"session_id": "*"},
    {"operator_id": "a" * 65},
])
def test_operator_command_value_outside_its_bounds_is_out_of_range(changes):
    with pytest.raises(OutOfRange):
        command(**changes)


@pytest.mark.parametrize("changes", [
    {"k_h": -0.1}, {"k_s": 1.5}, {"active_group": 2}, {"authority": "robot"}, {"group_classes": ["unsafe"]},
    {"lease_holder": "a b"},
])
def test_robot_state_value_outside_its_bounds_is_out_of_range(changes):
    with pytest.raises(OutOfRange):
        state(**changes)


def test_loss_fraction_above_one_is_out_of_range():
    with pytest.raises(OutOfRange):
        m.LinkHealth(operator_latency_ms=0.0, loss_fraction=1.5, staleness_ms=0.0, can_feedback_age_ms=0.0)


@pytest.mark.parametrize("text", ["\x1b[31mred", "nul\x00", "\x85", "\ud800"])
def test_event_text_with_control_characters_or_surrogates_is_out_of_range(text):
    with pytest.raises(OutOfRange):
        m.Event(seq=0, time=0.0, kind="fault", severity="error", source="ctl", text=text)


def test_event_text_may_hold_tabs_newlines_and_unicode():
    assert m.Event(seq=0, time=0.0, kind="info", severity="info", source="ctl", text="a\tb\né✓").text == "a\tb\né✓"


def test_project_dims_are_three_dof_three_theta_three_wheels():
    assert (ROBOT_DIMS.dof, ROBOT_DIMS.n_theta, ROBOT_DIMS.n_wheels) == (3, 3, 3)


@pytest.mark.parametrize("dims", [(0, 3, 3), (9, 3, 3), (3, 17, 3), (3, 3, 0), (3, 3, 9)])
def test_dims_outside_the_protocol_bounds_are_out_of_range(dims):
    with pytest.raises(OutOfRange):
        Dims(*dims)
