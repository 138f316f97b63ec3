"""The console's lease client (services/console/lease_client.py) against a stand-in session: pure."""
from types import SimpleNamespace

from sharedctl.protocol.messages import LeaseAction, LeaseReply, LeaseRequest
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.services.console.lease_client import HAND_BACK_TIMEOUT, QUERY_TIMEOUT, LeaseClient


class Payload:
    def __init__(self, data):
        self.data = data

    def to_bytes(self):
        return self.data


class StandIn:
    """`session.get` answered by a function of the request (None: nobody answers)."""

    def __init__(self, answer):
        self.answer, self.requests, self.attachments, self.qos, self.timeouts = answer, [], [], [], []

    def get(self, key, payload, timeout, attachment=None, **qos):
        self.qos.append(qos)
        self.timeouts.append(timeout)
        request = decode_message(payload, None, expect=LeaseRequest)
        self.requests.append((key, request))
        self.attachments.append((payload, attachment))
        reply = self.answer(request)
        return [] if reply is None else [SimpleNamespace(ok=SimpleNamespace(payload=Payload(encode_message(reply))))]


def reply(request, granted, holder, t=1000.0):
    return LeaseReply(request_seq=request.seq, time=t, granted=granted, holder=holder, reason="r")


def test_a_granted_take_means_holding_and_names_the_lease_key():
    client = LeaseClient("r1", "alice", "a1")
    session = StandIn(lambda req: reply(req, True, "alice"))
    assert client.ask(session, LeaseAction.TAKE).granted and client.holding
    assert session.requests[0][0] == "sharedctl/v1/r1/control/lease"
    assert client.status() == "held by this console"


def test_a_lease_query_asks_for_the_control_paths_qos():
    import zenoh

    session = StandIn(lambda req: reply(req, True, "alice"))
    LeaseClient("r1", "alice", "a1").ask(session, LeaseAction.TAKE)
    assert session.qos == [{"priority": zenoh.Priority.REAL_TIME, "congestion_control": zenoh.CongestionControl.BLOCK,
                            "express": True}]


def test_a_refused_take_shows_the_holder():
    client = LeaseClient("r1", "bob", "b1")
    client.ask(StandIn(lambda req: reply(req, False, "alice")), LeaseAction.TAKE)
    assert not client.holding and client.status().startswith("held by alice")


def test_no_answer_leaves_it_not_holding():
    client = LeaseClient("r1", "alice", "a1")
    assert client.ask(StandIn(lambda req: None), LeaseAction.TAKE) is None and not client.holding
    assert "no answer" in client.status()


def test_each_query_has_a_new_sequence_number():
    client = LeaseClient("r1", "alice", "a1")
    session = StandIn(lambda req: reply(req, True, "alice"))
    client.ask(session, LeaseAction.TAKE)
    client.ask(session, LeaseAction.RELEASE)
    assert [r.seq for _, r in session.requests] == [1, 2] and not client.holding


def test_a_state_newer_than_the_grant_naming_nobody_ends_holding():
    client = LeaseClient("r1", "alice", "a1")
    client.ask(StandIn(lambda req: reply(req, True, "alice", t=1000.0)), LeaseAction.TAKE)
    client.on_state(None, 999.9)                 # sent before the grant: ignored
    assert client.holding
    client.on_state(None, 1000.5)                # the lease expired
    assert not client.holding


def test_a_reply_to_another_request_is_ignored():
    client = LeaseClient("r1", "alice", "a1")
    stale = StandIn(lambda req: LeaseReply(request_seq=req.seq + 7, time=1.0, granted=True, holder="alice", reason=""))
    assert client.ask(stale, LeaseAction.TAKE) is None and not client.holding


def test_a_refused_release_also_means_not_holding():
    client = LeaseClient("r1", "alice", "a1")
    client.ask(StandIn(lambda req: reply(req, True, "alice")), LeaseAction.TAKE)
    client.ask(StandIn(lambda req: reply(req, False, None)), LeaseAction.RELEASE)   # already released in-band
    assert not client.holding


def test_a_console_that_ends_holding_control_hands_it_back_with_one_short_release():
    client = LeaseClient("r1", "alice", "a1")
    session = StandIn(lambda req: reply(req, req.action is LeaseAction.TAKE, "alice" if req.action is LeaseAction.TAKE
                                        else None))
    client.ask(session, LeaseAction.TAKE)
    assert client.hand_back(session)
    assert [r.action for _, r in session.requests] == [LeaseAction.TAKE, LeaseAction.RELEASE]
    assert session.timeouts[-1] == HAND_BACK_TIMEOUT < QUERY_TIMEOUT
    assert not client.holding and not client.wants


def test_a_console_that_holds_nothing_hands_nothing_back():
    client = LeaseClient("r1", "alice", "a1")
    session = StandIn(lambda req: reply(req, False, "bob"))
    client.ask(session, LeaseAction.TAKE)                       # refused: bob holds it
    assert not client.hand_back(session)
    assert [r.action for _, r in session.requests] == [LeaseAction.TAKE]


def test_a_hand_back_nobody_answers_leaves_the_lease_to_expire():
    client = LeaseClient("r1", "alice", "a1")
    client.ask(StandIn(lambda req: reply(req, True, "alice")), LeaseAction.TAKE)
    assert not client.hand_back(StandIn(lambda req: None))
    assert client.reason == "no answer from the controller"


def test_with_a_signer_every_query_carries_a_signature_the_controllers_list_verifies(tmp_path):
    from sharedctl.protocol.keys import lease_key
    from sharedctl.services.security import credentials
    from sharedctl.services.security.signing import Signer, TrustList

    site = credentials.generate(tmp_path, operators={"alice": ("r1",)})
    client = LeaseClient("r1", "alice", "a1", signer=Signer.from_file(site.signing_key("alice"), "alice"))
    session = StandIn(lambda req: reply(req, True, "alice"))
    client.ask(session, LeaseAction.TAKE)
    client.ask(session, LeaseAction.RELEASE)
    verify = TrustList.from_file(site.trust_file).verifier(lease_key("r1"), "r1")
    assert [verify(payload, attachment) for payload, attachment in session.attachments] == [("alice", None)] * 2
    assert LeaseClient("r1", "alice", "a1").signer is None
