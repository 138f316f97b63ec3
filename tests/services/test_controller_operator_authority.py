"""The operator policy with the lease and the replay guard (operator_input.py + lease.py + replay_guard.py): pure."""
import numpy as np

from sharedctl.protocol.messages import ControlRequest, OperatorCommand
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.services.controller.lease import LeaseMode, OperatorLease
from sharedctl.services.controller.operator_input import OperatorInputPolicy

KP = np.array([20.0, 20.0, 5.0])
POSE = np.array([0.0, 0.0, 0.0])


def command(op, session, seq, *, joystick=(0.5, 0.0, 0.0), estop=False, request=ControlRequest.NONE, sent=100.0):
    return OperatorCommand(operator_id=op, session_id=session, seq=seq, send_time=sent, joystick=joystick,
                           q_d=(0.0, 0.0, 0.0), qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True,
                           estop=estop, control_request=request)


def offer(policy, cmd, now, delay=0.005):
    return policy.offer(encode_message(cmd), now, wall_now=cmd.send_time + delay)


def test_a_non_holders_commands_have_no_effect_and_are_counted():
    policy = OperatorInputPolicy(KP)
    assert offer(policy, command("alice", "a1", 1), 10.0)
    assert not offer(policy, command("mallory", "m1", 1, joystick=(-1.0, -1.0, 0.0)), 10.01)
    op, status = policy.operator_input(10.02, POSE)
    np.testing.assert_allclose(op.force, KP * [0.5, 0.0, 0.0])
    assert status.operator_id == "alice" and policy.rejections == {"not_holder": 1}


def test_an_estop_from_a_non_holder_is_honoured():
    policy = OperatorInputPolicy(KP)
    offer(policy, command("alice", "a1", 1), 10.0)
    assert not offer(policy, command("bob", "b1", 1, estop=True), 10.01)   # not accepted as a command …
    assert policy.operator_input(10.02, POSE)[1].estop_requested          # … but the estop holds


def test_a_replayed_estop_still_stops_it_is_the_safe_direction():
    policy = OperatorInputPolicy(KP)
    stop = command("alice", "a1", 1, estop=True)
    offer(policy, stop, 10.0)
    policy.clear_estop()
    offer(policy, stop, 10.5)                                             # duplicate seq
    assert policy.operator_input(10.5, POSE)[1].estop_requested


def test_replayed_and_out_of_order_commands_have_no_effect():
    policy = OperatorInputPolicy(KP)
    old = command("alice", "a1", 1, joystick=(1.0, 0.0, 0.0))
    offer(policy, old, 10.0)
    newest = command("alice", "a1", 3, joystick=(0.0, 0.5, 0.0), sent=100.04)
    offer(policy, newest, 10.04)
    assert not offer(policy, old, 10.05)                                  # replay of an older one
    assert not offer(policy, newest, 10.05)                               # replay of the newest
    assert not offer(policy, command("alice", "a1", 2, joystick=(-1.0, 0.0, 0.0), sent=100.02), 10.06)  # overtaken
    np.testing.assert_allclose(policy.operator_input(10.07, POSE)[0].force, KP * [0.0, 0.5, 0.0])
    assert policy.rejections == {"duplicate_seq": 1, "out_of_order_seq": 2}


def test_a_command_delivered_too_late_is_stale_and_dropped():
    policy = OperatorInputPolicy(KP)
    offer(policy, command("alice", "a1", 1, sent=100.0), 10.0, delay=0.005)
    assert not offer(policy, command("alice", "a1", 2, joystick=(-1.0, 0.0, 0.0), sent=100.02), 10.7, delay=0.7)
    assert policy.rejections == {"stale": 1}
    np.testing.assert_allclose(policy.operator_input(10.1, POSE)[0].force, KP * [0.5, 0.0, 0.0])


def test_after_the_lease_expires_the_last_command_no_longer_drives():
    policy = OperatorInputPolicy(KP)
    offer(policy, command("alice", "a1", 1), 10.0)
    op, status = policy.operator_input(11.5, POSE)
    assert status.hands_off and status.reason == "no_lease" and not np.any(op.force)
    assert policy.lease.holder is None


def test_explicit_mode_before_any_take_commands_are_refused_then_a_take_gives_control():
    policy = OperatorInputPolicy(KP, lease=OperatorLease(mode=LeaseMode.EXPLICIT))
    assert not offer(policy, command("alice", "a1", 1), 10.0)
    assert policy.rejections == {"no_lease": 1} and policy.operator_input(10.0, POSE)[1].reason == "no_command"
    assert offer(policy, command("alice", "a1", 2, request=ControlRequest.TAKE), 10.02)
    assert offer(policy, command("alice", "a1", 3), 10.04)
    assert not policy.operator_input(10.05, POSE)[1].hands_off


def test_another_sender_naming_the_holders_session_cannot_push_its_sequence_ahead():
    policy = OperatorInputPolicy(KP)
    offer(policy, command("alice", "a1", 1), 10.0)
    assert not offer(policy, command("mallory", "a1", 2**64 - 1), 10.01)     # not the holder
    assert offer(policy, command("alice", "a1", 2, joystick=(0.0, 0.5, 0.0)), 10.02)
    np.testing.assert_allclose(policy.operator_input(10.03, POSE)[0].force, KP * [0.0, 0.5, 0.0])
