"""RobotState and Event building (services/controller/telemetry.py)."""
from dataclasses import replace

import numpy as np
import pytest

from sharedctl.protocol.errors import NonFiniteValue
from sharedctl.protocol.messages import RobotState
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.protocol.wire_types import ROBOT_DIMS
from sharedctl.services.controller.telemetry import EventLimiter, Link, robot_state
from sharedctl.services.scenario_files import load
from sharedctl.sets import classify_rows
from sharedctl.shared_controller import OperatorInput, SharedController
from sharedctl.sharing import Authority
from sharedctl.transform import Desired


@pytest.fixture(scope="module")
def stepped():
    loop, q0, _ = load("paper_convex").closed_loop("ce")
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference)
    state = ctrl.initial_state(q0, loop.theta_hat0)
    q, v = np.array([-0.9, 3.97, 0.0]), np.array([0.0, 0.5, 0.0])       # 3 cm from the top face y = 4, closing
    op = OperatorInput(Desired(q.copy(), np.zeros(3), np.zeros(3)), np.array([0.0, 10.0, 0.0]), 2.5)
    state, out = ctrl.step(state, q, v, op, 0.002)
    return loop, q, v, out


def build(loop, q, v, out, **kw):
    args = dict(seq=7, time=1.0e9, q=q, v=v, out=out, feasible=loop.feasible, bands=loop.sharing.bands,
                estop_active=False, lease_holder="op1", link=Link(0.004, 0.1, 0.02, 0.003))
    if out is not None:
        args.update(wheel_torques=loop.model.wheel_torques(q, out.u_s), u_s=out.u_s, theta_hat=out.theta_estimate)
    args.update(kw)
    return robot_state(**args)


def test_robot_state_maps_the_step_output_and_round_trips_the_wire(stepped):
    loop, q, v, out = stepped
    msg = decode_message(encode_message(build(loop, q, v, out), ROBOT_DIMS), expect=RobotState)
    assert out.authority is Authority.MACHINE                              # hazardous: the machine acts
    assert msg.authority.value == "machine" and msg.k_s == 0.0 and msg.k_f == pytest.approx(out.k_f)
    assert msg.active_group == out.group
    assert len(msg.group_classes) == len(loop.feasible.groups)
    assert "hazard" in {c.value for c in msg.group_classes}
    np.testing.assert_allclose(msg.q_ref, out.q_r)
    np.testing.assert_allclose(msg.u_s, out.u_s)
    np.testing.assert_allclose(msg.u_f, out.u_f)
    np.testing.assert_allclose(msg.u_h, out.u_h)
    np.testing.assert_allclose(msg.wheel_torques, loop.model.wheel_torques(q, out.u_s), rtol=1e-12)
    assert msg.min_margin == pytest.approx(0.03) and msg.region_margins == pytest.approx((0.03,))
    assert msg.link.operator_latency_ms == pytest.approx(4.0) and msg.link.staleness_ms == pytest.approx(20.0)
    assert msg.link.can_feedback_age_ms == pytest.approx(3.0) and msg.link.loss_fraction == pytest.approx(0.1)


def test_human_authority_has_k_s_one(stepped):
    loop, q, v, out = stepped
    msg = build(loop, q, v, replace(out, authority=Authority.HUMAN, group=None))
    assert msg.authority.value == "human" and msg.k_s == 1.0 and msg.active_group is None


def test_a_missing_projected_reference_falls_back_to_the_pose_and_never_is_inf(stepped):
    loop, q, v, out = stepped
    msg = build(loop, q, v, replace(out, reference=np.full(3, np.nan)), link=Link(0.0, 0.0, float("inf"), float("inf")))
    np.testing.assert_allclose(msg.q_ref, q)
    encode_message(msg, ROBOT_DIMS)
    assert msg.link.staleness_ms == 1e9


def test_before_the_first_step_the_state_reports_the_operator_in_charge_and_theta_hat0(stepped):
    loop, q, v, _ = stepped
    msg = build(loop, q, v, None, u_s=np.zeros(3), wheel_torques=np.zeros(3), theta_hat=np.zeros(3))
    encode_message(msg, ROBOT_DIMS)
    assert msg.authority.value == "human" and msg.theta_hat == (0.0, 0.0, 0.0)


def classify_rows_per_group(loop, q, v):
    with np.errstate(invalid="ignore"):
        return tuple(classify_rows(g.values(q), g.K @ v, loop.sharing.bands).name for g in loop.feasible.groups)


def before_the_first_step(loop, q, v, **kw):
    return build(loop, q, v, None, u_s=np.zeros(3), wheel_torques=np.zeros(3), theta_hat=np.zeros(3), **kw)


@pytest.mark.parametrize("name", ["paper_convex", "paper_nonconvex"])
def test_group_classes_and_margins_are_classify_rows_and_the_feasible_sets_margins(name):
    loop = load(name).closed_loop("ce")[0]
    q, v = np.array([-0.2, 0.1, 0.4]), np.array([0.7, 0.5, -0.2])
    msg = before_the_first_step(loop, q, v)
    assert tuple(c.name for c in msg.group_classes) == classify_rows_per_group(loop, q, v)
    assert msg.min_margin == loop.feasible.margin(q) == max(msg.region_margins)
    assert msg.region_margins == tuple(loop.feasible.region_margins(q).tolist())


def test_margins_far_outside_the_set_are_clipped_to_minus_1e12(stepped):
    loop, _, v, _ = stepped
    msg = before_the_first_step(loop, np.array([-1.0e13, 3.0, 0.0]), v)
    assert msg.min_margin == -1.0e12 and msg.region_margins == (-1.0e12,)


def test_a_non_finite_pose_is_refused_for_its_margin(stepped):
    loop, _, v, out = stepped
    with pytest.raises(NonFiniteValue, match="min_margin"):
        build(loop, np.array([-0.9, np.nan, 0.0]), v, out)


def test_a_non_finite_velocity_is_sent_as_zero_with_the_classes_classify_rows_gives_it(stepped):
    loop, q, _, _ = stepped
    v = np.array([0.0, np.inf, 0.0])
    msg = before_the_first_step(loop, q, v)
    assert msg.qd_hat == (0.0, 0.0, 0.0)
    assert tuple(c.name for c in msg.group_classes) == classify_rows_per_group(loop, q, v)


def test_a_pose_of_the_wrong_length_is_refused(stepped):
    loop, _, v, _ = stepped
    with pytest.raises(ValueError):
        before_the_first_step(loop, np.array([-0.9, 3.0]), v)


def test_events_of_one_topic_are_rate_limited_and_the_suppressed_count_reported():
    limiter = EventLimiter(interval=1.0)
    assert limiter.make(0.0, 5.0, "rej", "rejection", "warning", "bad") is not None
    assert limiter.make(0.5, 5.5, "rej", "rejection", "warning", "bad") is None
    assert limiter.make(0.6, 5.6, "other", "info", "info", "x") is not None
    ev = limiter.make(1.2, 6.2, "rej", "rejection", "warning", "bad")
    assert ev.text == "bad (+1 similar suppressed)" and ev.seq == 3 and ev.source == "controller"
