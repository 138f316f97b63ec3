"""Operator commands → OperatorInput: the staleness and ordering policy (services/controller/operator_input.py)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from sharedctl.protocol.messages import ControlRequest, OperatorCommand
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.services.controller.operator_input import OperatorInputPolicy

KP = np.array([20.0, 20.0, 5.0])
POSE = np.array([-0.9, 3.0, 0.0])


def command(seq, *, session="s1", joystick=(0.5, -0.25, 0.1), deadman=True, estop=False, send_time=100.0,
            request=ControlRequest.NONE, q_d=(-0.5, 2.0, 0.0)):
    return OperatorCommand(
        operator_id="op1", session_id=session, seq=seq, send_time=send_time, joystick=joystick, q_d=q_d,
        qd_d=(0.1, 0.2, 0.0), qdd_d=(0.0, 0.01, 0.0), deadman=deadman, estop=estop, control_request=request,
    )


def offer(policy, cmd, now):
    """`cmd` received at `now`; one with the default send time is stamped by a sender whose clock runs with the
    controller's, 4 ms of delivery before it."""
    if cmd.send_time == 100.0:
        cmd = replace(cmd, send_time=100.0 + now)
    return policy.offer(encode_message(cmd), now, wall_now=cmd.send_time + 0.004)


def test_fresh_command_gives_the_spring_force_intent_and_wish():
    policy = OperatorInputPolicy(KP)
    assert offer(policy, command(1), now=10.0)
    op, status = policy.operator_input(10.1, POSE)
    d = np.array([0.5, -0.25, 0.1])
    np.testing.assert_allclose(op.force, KP * d)                       # (44)
    assert op.intent == pytest.approx(3.15)        # (45): ½(20·0.5² + 20·0.25² + 5·0.1²), by hand
    np.testing.assert_allclose(op.desired.q, [-0.5, 2.0, 0.0])
    np.testing.assert_allclose(op.desired.q_dot, [0.1, 0.2, 0.0])
    np.testing.assert_allclose(op.desired.q_ddot, [0.0, 0.01, 0.0])
    assert not status.hands_off and status.reason == "active"
    assert status.latency == pytest.approx(0.004)


def test_before_any_command_the_wish_is_the_current_pose_hands_off():
    op, status = OperatorInputPolicy(KP).operator_input(0.0, POSE)
    np.testing.assert_array_equal(op.desired.q, POSE)
    np.testing.assert_array_equal(op.desired.q_dot, np.zeros(3))
    np.testing.assert_array_equal(op.force, np.zeros(3))
    assert op.intent == 0.0 and status.hands_off and status.reason == "no_command"


def test_operator_silent_for_more_than_300_ms_is_hands_off_with_the_wish_held():
    policy = OperatorInputPolicy(KP)
    offer(policy, command(1), now=10.0)
    assert not policy.operator_input(10.29, POSE)[1].hands_off
    op, status = policy.operator_input(10.31, POSE)
    assert status.hands_off and status.reason == "stale"
    np.testing.assert_array_equal(op.force, np.zeros(3))
    assert op.intent == 0.0
    np.testing.assert_allclose(op.desired.q, [-0.5, 2.0, 0.0])         # held at the last q_d
    np.testing.assert_array_equal(op.desired.q_dot, np.zeros(3))       # with zero rates
    np.testing.assert_array_equal(op.desired.q_ddot, np.zeros(3))


def test_released_deadman_is_hands_off():
    policy = OperatorInputPolicy(KP)
    offer(policy, command(1, deadman=False), now=10.0)
    op, status = policy.operator_input(10.0, POSE)
    assert status.hands_off and status.reason == "deadman"
    assert op.intent == 0.0 and not np.any(op.force)


def test_older_and_duplicate_seqs_are_ignored_and_counted():
    policy = OperatorInputPolicy(KP)
    assert offer(policy, command(5, joystick=(0.2, 0.0, 0.0)), now=10.0)
    assert not offer(policy, command(5, joystick=(0.9, 0.0, 0.0)), now=10.01)
    assert not offer(policy, command(3, joystick=(-0.9, 0.0, 0.0)), now=10.02)
    op, _ = policy.operator_input(10.03, POSE)
    np.testing.assert_allclose(op.force, KP * np.array([0.2, 0.0, 0.0]))
    assert policy.rejections == {"duplicate_seq": 1, "out_of_order_seq": 1}


def test_a_new_session_starts_its_own_sequence_once_the_old_one_has_let_go():
    policy = OperatorInputPolicy(KP)
    offer(policy, command(100, session="old"), now=10.0)
    assert not offer(policy, command(1, session="new"), now=10.1)     # the old session still holds the lease
    assert policy.rejections == {"not_holder": 1}
    assert offer(policy, command(2, session="new", joystick=(0.0, 1.0, 0.0)), now=11.1)   # lease expired (1 s)
    np.testing.assert_allclose(policy.operator_input(11.1, POSE)[0].force, [0.0, 20.0, 0.0])


def test_malformed_payloads_are_counted_not_raised_and_make_the_operator_hands_off():
    policy = OperatorInputPolicy(KP)
    offer(policy, command(1), now=10.0)
    for junk in (b"", b"\xc1", b"\x81\xa4type\xa3bad", encode_message(command(2))[:-3], b"\x00" * 5000):
        assert policy.offer(junk, 10.01) is False
    assert policy.rejected == 5
    assert policy.operator_input(10.02, POSE)[1].reason == "rejected"
    assert offer(policy, command(3), now=10.03)                       # the next valid command restores it
    assert not policy.operator_input(10.03, POSE)[1].hands_off


def test_wrong_dimension_command_is_rejected():
    policy = OperatorInputPolicy(KP)
    bad = OperatorCommand(
        operator_id="op1", session_id="s1", seq=1, send_time=1.0, joystick=(0.0, 0.0), q_d=(0.0, 0.0),
        qd_d=(0.0, 0.0), qdd_d=(0.0, 0.0), deadman=True, estop=False, control_request=ControlRequest.NONE,
    )
    assert not policy.offer(encode_message(bad), 1.0)
    assert policy.rejections == {"WrongLength": 1}


def test_estop_flag_latches_until_cleared():
    policy = OperatorInputPolicy(KP)
    offer(policy, command(1, estop=True), now=10.0)
    offer(policy, command(2), now=10.01)
    assert policy.operator_input(10.02, POSE)[1].estop_requested
    policy.clear_estop()
    assert not policy.operator_input(10.02, POSE)[1].estop_requested


def test_loss_fraction_is_estimated_from_seq_gaps():
    policy = OperatorInputPolicy(KP)
    for seq in range(1, 101):
        if seq % 4 != 0:                       # every 4th command lost
            offer(policy, command(seq), now=10.0 + seq * 0.01)
    assert policy.loss_fraction() == pytest.approx(1 - 75 / 99, abs=1e-9)


def test_latency_is_unknown_when_clocks_disagree():
    policy = OperatorInputPolicy(KP)
    policy.offer(encode_message(command(1, send_time=5000.0)), 10.0, wall_now=10.0)
    assert policy.operator_input(10.0, POSE)[1].latency == 0.0
    assert math.isfinite(policy.operator_input(10.0, POSE)[1].staleness)


def test_the_input_follows_every_new_command_and_every_change_of_hands_off():
    """The input is built once per (command, hands-off) and handed out again, read-only, until either changes."""
    policy = OperatorInputPolicy(KP)
    now = 10.0
    for seq, joystick in enumerate([(0.5, -0.25, 0.1), (0.5, -0.25, 0.1), (-1.0, 0.0, 0.3), (0.0, 0.0, 0.0)], start=1):
        assert offer(policy, command(seq, joystick=joystick, q_d=(seq, 2.0, 0.0)), now)
        first, _ = policy.operator_input(now + 0.01, POSE)
        again, status = policy.operator_input(now + 0.02, POSE)
        assert again is first and not status.hands_off
        np.testing.assert_allclose(first.force, KP * np.array(joystick))
        np.testing.assert_allclose(first.desired.q, [seq, 2.0, 0.0])
        with pytest.raises(ValueError):
            first.force[0] = 1.0
        stale, status = policy.operator_input(now + 0.31, POSE)
        assert status.hands_off and stale.intent == 0.0 and not np.any(stale.force)
        now += 0.5


def test_a_flood_of_sessions_without_the_lease_cannot_make_a_captured_command_of_the_holder_new():
    """Threat: sessions that never held the lease push the holder's out of the replay guard's memory, and a
    captured command of the holder then passes as new and renews the lease (docs/security.md)."""
    policy = OperatorInputPolicy(KP)
    captured = command(7, request=ControlRequest.TAKE)
    assert offer(policy, captured, now=10.0) and policy.lease.holder_id == "op1"
    for k in range(3 * 64):
        junk = OperatorCommand(operator_id=f"intruder{k}", session_id=f"x{k}", seq=1, send_time=100.0,
                               joystick=(1.0, 1.0, 0.0), q_d=(0.0, 0.0, 0.0), qd_d=(0.0, 0.0, 0.0),
                               qdd_d=(0.0, 0.0, 0.0), deadman=True, estop=False, control_request=ControlRequest.NONE)
        assert not offer(policy, junk, now=10.0 + 1e-4 * k)
    accepted = policy.accepted
    assert not offer(policy, captured, now=10.2)
    assert policy.accepted == accepted and policy.rejections["duplicate_seq"] == 1
