"""Answering lease queries (`…/control/lease`): payload in, `LeaseReply` out. Pure (the caller gives the times).

A query's payload is a `LeaseRequest`. It goes through its own `ReplayGuard` (lease requests
have their own sequence per session: a replayed or stale take does nothing) and then to the
`OperatorLease`. Every query gets a reply, a refusal included, so a console never waits for
its timeout to learn why. Refusals are counted by reason, prefixed `lease_`:
`lease_refused` (another session holds control, or a release by a non-holder), and
`lease_duplicate_seq`, `lease_out_of_order_seq`, `lease_stale`, `lease_clock_skew`,
`lease_rate_limited` (more than the session's rate: admission.py), or the decoder's error name
(`lease_MalformedPayload`, …). With `verify` (operator identity, services/security/signing.py) a
query first needs a valid signature over this robot's lease key and the payload by an operator
trusted for this robot, and the request's `operator_id` must be the signer's: otherwise
`lease_unsigned`, `lease_bad_attachment`, `lease_unknown_operator`, `lease_not_permitted`,
`lease_bad_signature` or `lease_identity_mismatch`, refused (the reply names the reason and
answers the request's seq) before the replay guard or the rate limit see it.
"""
from __future__ import annotations

from collections import Counter

from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.messages import LeaseReply, LeaseRequest
from sharedctl.protocol.msgpack_codec import decode_message
from sharedctl.protocol.wire_types import MAX_TEXT_LEN

from .admission import RateLimit
from .lease import OperatorLease
from .replay_guard import ReplayGuard


def answer(payload: bytes, lease: OperatorLease, guard: ReplayGuard, rejections: Counter,
           now: float, wall_now: float, limit: RateLimit | None = None, attachment: bytes | None = None,
           verify=None) -> LeaseReply:
    """The reply to one lease query received at `now` (s, monotonic) / `wall_now` (s, wall clock); `limit`: the
    queries' rate per session; `verify`: (payload, attachment) -> (signer, reason), or None (no identity)."""
    try:
        request = decode_message(bytes(payload), None, expect=LeaseRequest)
    except ProtocolError as exc:
        rejections[f"lease_{type(exc).__name__}"] += 1
        return _reply(0, wall_now, False, lease, now, f"malformed lease request: {type(exc).__name__}")
    except Exception as exc:  # noqa: BLE001 — a bad payload never escapes the queryable
        rejections[f"lease_unexpected_{type(exc).__name__}"] += 1
        return _reply(0, wall_now, False, lease, now, "malformed lease request")
    if verify is not None:         # decoded first only to answer the request's seq: the console learns why
        signer, reason = verify(payload, attachment)
        if reason is None and request.operator_id != signer:
            reason = "identity_mismatch"
        if reason is not None:
            rejections[f"lease_{reason}"] += 1
            return _reply(request.seq, wall_now, False, lease, now, f"request refused: {reason}")
    key = f"{request.operator_id}/{request.session_id}"
    reason = guard.admit(key, request.seq, request.time, now, wall_now)
    if reason is None and limit is not None and not limit.admit(key, now):
        reason = "rate_limited"
    if reason is not None:
        rejections[f"lease_{reason}"] += 1
        return _reply(request.seq, wall_now, False, lease, now, f"request dropped: {reason}")
    decision = lease.request(request.operator_id, request.session_id, request.action, now)
    if decision.granted:
        guard.pin(f"{request.operator_id}/{request.session_id}")    # kept through floods (replay_guard.py)
    else:
        rejections["lease_refused"] += 1
    return LeaseReply(request_seq=request.seq, time=max(wall_now, 0.0), granted=decision.granted,
                      holder=decision.holder, reason=decision.reason[:MAX_TEXT_LEN])


def _reply(seq: int, wall_now: float, granted: bool, lease: OperatorLease, now: float, reason: str) -> LeaseReply:
    lease.update(now)
    return LeaseReply(request_seq=seq, time=max(wall_now, 0.0), granted=granted, holder=lease.holder_id,
                      reason=reason[:MAX_TEXT_LEN])
