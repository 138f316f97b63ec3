"""Operator identity end to end, without the network: named operators' credentials and signing keys, the signature
attachment (protocol/signature.py), the controller's operators file and its verdicts (services/security/signing.py),
and what a verified identity changes in the command policy and the lease (operator_input.py, lease_queries.py).

Before identity, every operator shared one credential and the operator id inside a command was believed as sent: any
holder of the operator credential could name another operator's id and session and act as that operator."""
from __future__ import annotations

import stat
from collections import Counter
from dataclasses import replace

import msgpack
import numpy as np
import pytest

from sharedctl.protocol import keys
from sharedctl.protocol.errors import BadAttachment
from sharedctl.protocol.messages import ControlRequest, LeaseAction, LeaseRequest, OperatorCommand
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.protocol.signature import SIGNATURE_LEN, decode_attachment, encode_attachment
from sharedctl.services.controller import lease_queries
from sharedctl.services.controller.lease import OperatorLease
from sharedctl.services.controller.operator_input import OperatorInputPolicy
from sharedctl.services.controller.replay_guard import ReplayGuard
from sharedctl.services.security import credentials
from sharedctl.services.security.credentials_command import parse_operators
from sharedctl.services.security.roles import RoleError
from sharedctl.services.security.signing import Signer, SigningError, TrustList

KP = np.array([20.0, 20.0, 5.0])
POSE = np.array([0.0, 0.0, 0.0])
ROBOT, OTHER = "robot1", "robot2"
CMD_KEY, LEASE_KEY = keys.operator_cmd_key(ROBOT), keys.lease_key(ROBOT)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    return credentials.generate(tmp_path_factory.mktemp("site"),
                                operators={"alice": (ROBOT,), "bob": ("*",), "carol": (OTHER,)})


@pytest.fixture(scope="module")
def signers(site):
    return {name: Signer.from_file(site.signing_key(name), name) for name in site.operators}


@pytest.fixture()
def trust(site):
    return TrustList.from_file(site.trust_file)


def command(operator, seq, *, session=None, estop=False, request=ControlRequest.NONE, joystick=(0.5, 0.0, 0.0)):
    return OperatorCommand(operator_id=operator, session_id=session or f"{operator}-s", seq=seq,
                           send_time=100.0 + seq * 0.02, joystick=joystick, q_d=(0.1, 0.0, 0.0),
                           qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True, estop=estop,
                           control_request=request)


def signed(signer, cmd, key=CMD_KEY):
    payload = encode_message(cmd)
    return payload, (None if signer is None else signer.attachment(key, payload))


def policy_for(trust) -> OperatorInputPolicy:
    return OperatorInputPolicy(KP, verify=trust.verifier(CMD_KEY, ROBOT))


def offer(policy, payload_attachment, seq_time):
    payload, attachment = payload_attachment
    return policy.offer(payload, now=seq_time, wall_now=100.0 + seq_time, attachment=attachment)


# ----- credentials ------------------------------------------------------------------------
def test_each_named_operator_gets_its_own_user_certificate_password_and_signing_key(site):
    assert set(site.operators) == {"alice", "bob", "carol"} and "operator" not in site.users
    for name in site.operators:
        assert site.certificate(name).exists() and site.private_key(name).exists()
        assert stat.S_IMODE(site.signing_key(name).stat().st_mode) == 0o600
    assert len({site.users[n] for n in site.operators}) == 3          # three different passwords
    assert site.operators == {"alice": (ROBOT,), "bob": ("*",), "carol": (OTHER,)}


def test_the_operators_file_trusts_each_operator_for_its_robots_only(trust):
    assert {n: t.robots for n, t in trust.operators.items()} == {"alice": (ROBOT,), "bob": ("*",), "carol": (OTHER,)}
    assert trust.operators["alice"].permits(ROBOT) and not trust.operators["alice"].permits(OTHER)
    assert trust.operators["bob"].permits(OTHER)


def test_the_operator_option_takes_names_and_robot_lists():
    assert parse_operators(["alice=robot1,robot2", "bob"]) == {"alice": ("robot1", "robot2"), "bob": ("*",)}
    assert parse_operators(None) is None
    with pytest.raises(ValueError, match="twice"):
        parse_operators(["alice", "alice=robot1"])


@pytest.mark.parametrize("operators", [{"controller": ("*",)}, {"router": ("*",)}, {"a b": ("*",)},
                                       {"alice": ()}, {"alice": ("robot/1",)}])
def test_an_operator_name_or_robot_that_is_not_a_token_or_is_taken_is_refused(tmp_path, operators):
    with pytest.raises(RoleError):
        credentials.generate(tmp_path / "x", operators=operators)


@pytest.mark.parametrize("text, match", [
    ("x = 1", "unknown table"),
    ("[operators.alice]\npublic_key = 'AAAA'\nrobots = ['robot1']", "public_key"),
    ("[operators.alice]\npublic_key = 'AWW6ZoWMwSgWlX/0GC5+hOgt7xR7xampQSMiKndX+j8='\nrobots = []", "robots"),
    ("[operators.alice]\npublic_key = 'AWW6ZoWMwSgWlX/0GC5+hOgt7xR7xampQSMiKndX+j8='\nrobots = ['*']\nrole = 'x'",
     "only public_key"),
    ("[operators]", "at least one"),
    ("not toml [", "not TOML"),
])
def test_a_bad_operators_file_is_a_typed_error_naming_what_is_wrong(text, match):
    with pytest.raises(SigningError, match=match):
        TrustList.from_text(text)


def test_a_signing_key_that_is_not_ed25519_is_refused(site):
    with pytest.raises(SigningError, match="Ed25519"):
        Signer.from_file(site.private_key("alice"), "alice")        # the TLS key: ECDSA P-256


# ----- the attachment -------------------------------------------------------------------------
def test_the_attachment_round_trips_and_anything_else_is_bad_attachment():
    sig = bytes(range(SIGNATURE_LEN))
    assert decode_attachment(encode_attachment("alice", sig)).signer == "alice"
    bad = [b"", b"\xc1", msgpack.packb([1, 2]), msgpack.packb({"v": 2, "signer": "alice", "sig": sig}),
           msgpack.packb({"v": 1, "signer": "a/b", "sig": sig}), msgpack.packb({"v": 1, "signer": 7, "sig": sig}),
           msgpack.packb({"v": 1, "signer": "alice", "sig": sig[:10]}), b"\x00" * 300]
    for data in bad:
        with pytest.raises(BadAttachment):
            decode_attachment(data)


# ----- the verdicts ----------------------------------------------------------------------------
def test_the_verifier_names_each_reason_and_checks_a_signature_only_for_a_permitted_signer(site, signers, trust,
                                                                                         tmp_path):
    verify = trust.verifier(CMD_KEY, ROBOT)
    payload, attachment = signed(signers["alice"], command("alice", 1))
    assert verify(payload, attachment) == ("alice", None)
    assert verify(payload, None) == (None, "unsigned")
    assert verify(payload, b"junk") == (None, "bad_attachment")
    other_site = credentials.generate(tmp_path / "other", operators={"mallory": ("*",)})
    mallory = Signer.from_file(other_site.signing_key("mallory"), "mallory")
    assert verify(*signed(mallory, command("mallory", 1))) == (None, "unknown_operator")
    # a key of another site under a trusted name: the signature does not verify
    impostor = Signer(("alice"), Signer.from_file(other_site.signing_key("mallory"), "mallory").key)
    assert verify(*signed(impostor, command("alice", 1))) == (None, "bad_signature")
    assert verify(*signed(signers["carol"], command("carol", 1))) == (None, "not_permitted")
    tampered = payload.replace(b"alice-s", b"alice-t")
    assert tampered != payload and verify(tampered, attachment) == (None, "bad_signature")


def test_a_command_signed_for_one_robot_is_not_a_command_for_another_nor_a_lease_request(signers, trust):
    payload, attachment = signed(signers["bob"], command("bob", 1))                       # bob may command both
    assert trust.verifier(CMD_KEY, ROBOT)(payload, attachment) == ("bob", None)
    assert trust.verifier(keys.operator_cmd_key(OTHER), OTHER)(payload, attachment) == (None, "bad_signature")
    assert trust.verifier(LEASE_KEY, ROBOT)(payload, attachment) == (None, "bad_signature")


# ----- the command policy ------------------------------------------------------------------------
def test_a_signed_command_of_the_named_operator_drives(signers, trust):
    policy = policy_for(trust)
    assert offer(policy, signed(signers["alice"], command("alice", 1)), 1.0)
    op, status = policy.operator_input(1.01, POSE)
    assert not status.hands_off and status.operator_id == "alice" and policy.lease.holder_id == "alice"
    np.testing.assert_allclose(op.force, KP * [0.5, 0.0, 0.0])


def test_another_operator_naming_the_holder_cannot_act_for_it_nor_disturb_it(signers, trust):
    """bob knows alice's operator and session ids and her sequence; whatever he sends in her name is refused without
    touching her session: her next command is still new, her input is not made hands-off, the lease stays hers."""
    policy = policy_for(trust)
    assert offer(policy, signed(signers["alice"], command("alice", 1)), 1.0)
    forged = command("alice", 10**9, joystick=(-1.0, -1.0, -1.0), request=ControlRequest.RELEASE)
    assert not offer(policy, signed(signers["bob"], forged), 1.01)                  # bob's key, alice's name
    assert not offer(policy, signed(None, forged), 1.02)                            # no signature at all
    assert not offer(policy, (encode_message(forged), b"\x81\xa1v\x01"), 1.03)      # a broken attachment
    assert policy.rejections == Counter(identity_mismatch=1, unsigned=1, bad_attachment=1)
    status = policy.status(1.04)
    assert not status.hands_off and policy.lease.holder_id == "alice"
    assert offer(policy, signed(signers["alice"], command("alice", 2)), 1.05)       # her sequence was not advanced
    assert not offer(policy, signed(signers["bob"], command("bob", 1)), 1.06)       # bob as himself: not the holder
    assert policy.rejections["not_holder"] == 1


def test_an_unsigned_estop_stops_nothing_and_a_signed_one_of_any_permitted_operator_does(signers, trust):
    policy = policy_for(trust)
    offer(policy, signed(signers["alice"], command("alice", 1)), 1.0)
    offer(policy, signed(None, command("alice", 2, estop=True)), 1.01)
    offer(policy, signed(signers["carol"], command("carol", 1, estop=True)), 1.02)   # carol: not this robot
    assert not policy.estop_requested
    offer(policy, signed(signers["bob"], command("bob", 1, estop=True)), 1.03)      # not the holder, permitted
    assert policy.estop_requested


def test_without_an_operators_file_the_id_is_what_the_command_says():
    """The bench's single-operator mode, unchanged: no verification, an attachment is ignored."""
    policy = OperatorInputPolicy(KP)
    assert policy.offer(encode_message(command("alice", 1)), 1.0, 101.0, attachment=None)
    assert policy.lease.holder_id == "alice"


# ----- the lease ------------------------------------------------------------------------------------
def lease_query(signer, operator, seq, action, key=LEASE_KEY, session=None):
    payload = encode_message(LeaseRequest(operator_id=operator, session_id=session or f"{operator}-s", seq=seq,
                                          time=100.0 + seq, action=action))
    return payload, (None if signer is None else signer.attachment(key, payload))


def ask(lease, guard, rejections, query, now, trust):
    payload, attachment = query
    return lease_queries.answer(payload, lease, guard, rejections, now, 100.0 + now, attachment=attachment,
                                verify=trust.verifier(LEASE_KEY, ROBOT))


def test_the_lease_is_bound_to_the_verified_operator(signers, trust):
    lease, guard, rejections = OperatorLease(mode="explicit"), ReplayGuard(), Counter()
    unsigned = ask(lease, guard, rejections, lease_query(None, "alice", 1, LeaseAction.TAKE), 1.0, trust)
    assert not unsigned.granted and unsigned.request_seq == 1 and "unsigned" in unsigned.reason   # says why
    assert ask(lease, guard, rejections, lease_query(signers["alice"], "alice", 2, LeaseAction.TAKE), 1.1,
               trust).granted
    # bob, with alice's names, releases; then takes as alice: both refused, alice keeps control
    for k, action in enumerate((LeaseAction.RELEASE, LeaseAction.TAKE)):
        reply = ask(lease, guard, rejections, lease_query(signers["bob"], "alice", 50 + k, action), 1.2 + k / 10, trust)
        assert not reply.granted and reply.holder == "alice" and "identity_mismatch" in reply.reason
    carol = ask(lease, guard, rejections, lease_query(signers["carol"], "carol", 1, LeaseAction.TAKE), 1.5, trust)
    assert not carol.granted and "not_permitted" in carol.reason
    assert lease.holder_id == "alice" and lease.holder.session_id == "alice-s"
    assert rejections == Counter(lease_unsigned=1, lease_identity_mismatch=2, lease_not_permitted=1)
    # alice's own sequence was untouched by the forgeries: her release (seq 3) is new
    assert ask(lease, guard, rejections, lease_query(signers["alice"], "alice", 3, LeaseAction.RELEASE), 1.6,
               trust).granted


def test_a_lease_request_signed_for_another_robot_is_refused(signers, trust):
    lease, guard, rejections = OperatorLease(), ReplayGuard(), Counter()
    query = lease_query(signers["bob"], "bob", 1, LeaseAction.TAKE, key=keys.lease_key(OTHER))
    assert not ask(lease, guard, rejections, query, 1.0, trust).granted
    assert rejections == Counter(lease_bad_signature=1) and lease.holder is None


def test_a_replayed_signed_command_is_still_the_replay_guards(signers, trust):
    """A signature says who, never when: the captured command re-sent is a duplicate."""
    policy = policy_for(trust)
    captured = signed(signers["alice"], command("alice", 1))
    assert offer(policy, captured, 1.0)
    assert not offer(policy, captured, 1.1)
    assert policy.rejections == Counter(duplicate_seq=1)
    assert offer(policy, signed(signers["alice"], replace(command("alice", 2))), 1.2)
