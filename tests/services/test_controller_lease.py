"""The operator authority lease (services/controller/lease.py) and its queries (lease_queries.py): pure."""
from collections import Counter

import pytest

from sharedctl.protocol.messages import ControlRequest, LeaseAction, LeaseReply, LeaseRequest
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.services.controller import lease_queries
from sharedctl.services.controller.lease import LeaseMode, OperatorLease
from sharedctl.services.controller.replay_guard import ReplayGuard

TAKE, RELEASE, NONE = LeaseAction.TAKE, LeaseAction.RELEASE, ControlRequest.NONE


def test_a_take_when_free_is_granted_and_names_the_holder():
    lease = OperatorLease()
    decision = lease.request("alice", "a1", TAKE, 0.0)
    assert decision.granted and decision.holder == "alice" and lease.holds("alice", "a1", 0.0)


def test_a_take_while_another_holds_is_refused_and_says_who_holds():
    lease = OperatorLease()
    lease.request("alice", "a1", TAKE, 0.0)
    decision = lease.request("bob", "b1", TAKE, 0.5)
    assert not decision.granted and decision.holder == "alice" and "alice" in decision.reason


def test_the_same_operator_id_in_another_session_is_another_requester():
    lease = OperatorLease()
    lease.request("alice", "a1", TAKE, 0.0)
    assert not lease.request("alice", "a2", TAKE, 0.1).granted


def test_release_by_the_holder_frees_the_lease_for_the_next_take():
    lease = OperatorLease()
    lease.request("alice", "a1", TAKE, 0.0)
    assert lease.request("alice", "a1", RELEASE, 0.2).granted and lease.holder is None
    assert lease.request("bob", "b1", TAKE, 0.3).granted


def test_release_by_anyone_else_is_refused():
    lease = OperatorLease()
    lease.request("alice", "a1", TAKE, 0.0)
    assert not lease.request("bob", "b1", RELEASE, 0.1).granted
    assert lease.holder_id == "alice"


def test_the_lease_expires_without_renewal_within_the_stated_time():
    lease = OperatorLease(expiry=1.0)
    lease.request("alice", "a1", TAKE, 0.0)
    assert lease.admit_command("alice", "a1", NONE, 0.9) is None          # a command renews it
    assert lease.holds("alice", "a1", 1.9)
    assert not lease.holds("alice", "a1", 1.91)                           # 1.01 s since the last renewal
    assert lease.request("bob", "b1", TAKE, 1.95).granted
    assert [c.cause for c in lease.take_changes()] == ["taken", "expired", "taken"]


def test_commands_from_a_non_holder_are_refused_with_a_reason():
    lease = OperatorLease()
    lease.request("alice", "a1", TAKE, 0.0)
    assert lease.admit_command("bob", "b1", NONE, 0.1) == "not_holder"
    assert lease.admit_command("bob", "b1", ControlRequest.TAKE, 0.1) == "not_holder"
    assert lease.admit_command("alice", "a1", NONE, 0.1) is None


def test_implicit_mode_a_command_while_free_takes_the_lease():
    lease = OperatorLease(mode=LeaseMode.IMPLICIT)
    assert lease.admit_command("alice", "a1", NONE, 0.0) is None and lease.holder_id == "alice"
    assert lease.admit_command("bob", "b1", NONE, 0.1) == "not_holder"


def test_explicit_mode_commands_before_a_take_are_refused():
    lease = OperatorLease(mode=LeaseMode.EXPLICIT)
    assert lease.admit_command("alice", "a1", NONE, 0.0) == "no_lease" and lease.holder is None
    assert lease.admit_command("alice", "a1", ControlRequest.TAKE, 0.1) is None       # in-band take
    assert lease.admit_command("alice", "a1", NONE, 0.2) is None


def test_a_session_that_released_does_not_take_back_implicitly():
    lease = OperatorLease(mode=LeaseMode.IMPLICIT)
    lease.admit_command("alice", "a1", NONE, 0.0)
    assert lease.admit_command("alice", "a1", ControlRequest.RELEASE, 0.1) == "released"
    assert lease.admit_command("alice", "a1", NONE, 0.2) == "no_lease"
    assert lease.request("alice", "a1", TAKE, 0.3).granted


def test_expiry_must_be_positive():
    with pytest.raises(ValueError):
        OperatorLease(expiry=0.0)


# ----- queries ---------------------------------------------------------------
def request(op, session, seq, action, t=100.0):
    return encode_message(LeaseRequest(operator_id=op, session_id=session, seq=seq, time=t, action=action))


def ask(lease, guard, rejections, payload, now, wall=100.01):
    reply = lease_queries.answer(payload, lease, guard, rejections, now, wall)
    assert isinstance(reply, LeaseReply)
    return reply


def test_a_query_is_answered_with_the_decision_and_refusals_are_counted():
    lease, guard, rejections = OperatorLease(), ReplayGuard(), Counter()
    assert ask(lease, guard, rejections, request("alice", "a1", 1, "take"), 0.0).granted
    reply = ask(lease, guard, rejections, request("bob", "b1", 1, "take"), 0.1)
    assert (reply.granted, reply.holder, reply.request_seq) == (False, "alice", 1)
    assert rejections == {"lease_refused": 1}


def test_a_replayed_release_does_nothing():
    lease, guard, rejections = OperatorLease(), ReplayGuard(), Counter()
    ask(lease, guard, rejections, request("alice", "a1", 1, "take"), 0.0)
    release = request("alice", "a1", 2, "release")
    assert ask(lease, guard, rejections, release, 0.1).granted
    ask(lease, guard, rejections, request("alice", "a1", 3, "take"), 0.2)
    reply = ask(lease, guard, rejections, release, 0.3)                   # captured and re-sent
    assert not reply.granted and lease.holder_id == "alice"
    assert rejections == {"lease_out_of_order_seq": 1}


def test_a_malformed_query_gets_a_refusal_not_an_exception():
    lease, guard, rejections = OperatorLease(), ReplayGuard(), Counter()
    for junk in (b"", b"\xc1",
                 encode_message(LeaseReply(request_seq=1, time=1.0, granted=True, holder=None, reason=""))):
        assert not ask(lease, guard, rejections, junk, 0.0).granted
    assert sum(rejections.values()) == 3 and all(k.startswith("lease_") for k in rejections)


def test_holder_since_is_the_grant_instant_and_renewals_keep_it():
    lease = OperatorLease(expiry=1.0)
    assert lease.holder_since is None
    assert lease.admit_command("alice", "a1", NONE, 5.0) is None      # implicit take
    lease.admit_command("alice", "a1", NONE, 5.5)                     # renewals
    lease.request("alice", "a1", TAKE, 5.9)
    assert lease.holder_since == 5.0
    lease.update(7.0)                                                  # expired
    assert lease.holder_since is None
    lease.request("bob", "b1", TAKE, 7.2)
    assert lease.holder_since == 7.2


def test_a_flood_of_lease_queries_cannot_make_a_captured_take_of_the_holder_new():
    """Threat: refused sessions push the holder's out of the lease guard's memory; a captured take of the holder
    re-sent after it released would then take the lease back for it (docs/security.md)."""
    lease, guard, rejections = OperatorLease(), ReplayGuard(), Counter()
    take = request("alice", "a1", 1, "take")
    assert ask(lease, guard, rejections, take, 0.0).granted
    assert ask(lease, guard, rejections, request("alice", "a1", 2, "release"), 0.1).granted
    assert ask(lease, guard, rejections, request("bob", "b1", 1, "take"), 0.2).granted
    for k in range(3 * 64):
        ask(lease, guard, rejections, request(f"mallory{k}", f"m{k}", 1, "take"), 0.3)
    assert ask(lease, guard, rejections, request("bob", "b1", 2, "release"), 0.4).granted
    reply = ask(lease, guard, rejections, take, 0.5)                      # captured and re-sent
    assert not reply.granted and lease.holder is None
    assert rejections["lease_out_of_order_seq"] == 1
