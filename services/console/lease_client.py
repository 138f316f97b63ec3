"""The console's side of the operator authority lease: take and release control on `…/control/lease`.

`LeaseClient.run` (its own thread) asks the controller's queryable for what the operator wants:
a take while this console wants control and does not hold it (at start, again after an expiry,
and on T), a release when it holds control and no longer wants it (R). Each query carries its
own per-session sequence number and the wall-clock send time (the controller drops replayed,
out-of-order and stale lease requests). A query nobody answers (the controller is not up yet)
is retried every `retry` seconds. With a `signer` each query carries the operator's signature
(protocol/signature.py), which a controller with an operators file requires.

A console that ends cleanly hands control back (`hand_back`: one release, waiting at most
`HAND_BACK_TIMEOUT`): the controller takes authority at once instead of when the operator's
input goes stale, and another operator may take control without waiting for the lease to expire.

RobotState tells the console when it has lost control without asking (the lease expired or
was released in-band): `on_state` clears `holding` when a state newer than the grant names
another holder, or none. The console sends commands only while it holds control — and an
estop always (the controller honours an estop from any operator).
"""
from __future__ import annotations

import threading

from sharedctl.protocol import keys
from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.messages import LeaseAction, LeaseReply, LeaseRequest
from sharedctl.protocol.msgpack_codec import decode_message, encode_message

from .. import zenoh_qos
from ..lifecycle import steady_wall

RETRY = 0.25          # s between lease queries while what we want differs from what we have
QUERY_TIMEOUT = 0.5   # s a query waits for the controller's reply
HAND_BACK_TIMEOUT = 0.2   # s the release of a console that ends waits for its reply


class LeaseClient:
    """What this console wants (control or not) and what it has, kept in step with the controller."""

    def __init__(self, robot_id: str, operator_id: str, session_id: str, *, want: bool = True,
                 retry: float = RETRY, timeout: float = QUERY_TIMEOUT, signer=None) -> None:
        self.key = keys.lease_key(robot_id)
        self.signer = signer                 # security.signing.Signer: each query signed; None: unsigned
        self.operator_id, self.session_id = operator_id, session_id
        self.retry, self.timeout = retry, timeout
        self.lock = threading.Lock()
        self.wants = want
        self.holding = False
        self.holder: str | None = None       # as last reported by the controller (reply or RobotState)
        self.reason = "not asked yet"        # the last reply's reason
        self.granted_at = 0.0                # controller wall time of the last grant
        self.seq = 0
        self.queries = self.replies = 0

    # ----- what the operator wants ------------------------------------------
    def want(self, control: bool) -> None:
        with self.lock:
            self.wants = control

    def on_state(self, holder: str | None, state_time: float) -> None:
        """A RobotState (controller clock `state_time`) names the current lease holder."""
        with self.lock:
            if state_time <= self.granted_at:
                return                        # sent before our grant: says nothing about it
            self.holder = holder
            if self.holding and holder != self.operator_id:
                self.holding = False
                self.reason = "lease expired or released"

    def status(self) -> str:
        """One line for the dashboard."""
        with self.lock:
            if self.holding:
                return "held by this console"
            who = f"held by {self.holder}" if self.holder else "free"
            return f"{who} ({self.reason})"

    # ----- the thread -------------------------------------------------------
    def run(self, session, stop) -> None:
        while not stop.stopped:
            with self.lock:
                action = (LeaseAction.TAKE if self.wants and not self.holding
                          else LeaseAction.RELEASE if self.holding and not self.wants else None)
            if action is not None:
                self.ask(session, action)
            stop.wait(self.retry)

    def hand_back(self, session) -> bool:
        """At the console's end: release control if this console holds it. True if the controller
        answered the release (it says whether it was still ours); False if nothing was held or no
        answer came within HAND_BACK_TIMEOUT (the lease then expires as usual)."""
        with self.lock:
            self.wants = False
            holding = self.holding
        return holding and self.ask(session, LeaseAction.RELEASE, HAND_BACK_TIMEOUT) is not None

    def ask(self, session, action: LeaseAction, timeout: float | None = None) -> LeaseReply | None:
        """One query (waiting `timeout` s for the reply, default the client's); updates `holding` from the
        reply. None if nobody answered."""
        with self.lock:
            self.seq += 1
            request = LeaseRequest(operator_id=self.operator_id, session_id=self.session_id, seq=self.seq,
                                   time=steady_wall(), action=action)
        self.queries += 1
        reply = None
        try:
            payload = encode_message(request)
            attachment = None if self.signer is None else self.signer.attachment(self.key, payload)
            for answer in session.get(self.key, payload=payload, attachment=attachment,
                                      timeout=self.timeout if timeout is None else timeout,
                                      **zenoh_qos.options("lease")):
                if answer.ok is None:
                    continue
                try:
                    candidate = decode_message(answer.ok.payload.to_bytes(), None, expect=LeaseReply)
                except ProtocolError:
                    continue
                if candidate.request_seq == request.seq:
                    reply = candidate
        except Exception as exc:  # noqa: BLE001 — a failed query is retried, never fatal
            with self.lock:
                self.reason = f"query failed: {type(exc).__name__}"
            return None
        if reply is None:
            with self.lock:
                self.reason = "no answer from the controller"
            return None
        self.replies += 1
        with self.lock:
            self.holder, self.reason = reply.holder, reply.reason
            if action is LeaseAction.TAKE:
                self.holding = reply.granted
                if reply.granted:
                    self.granted_at = reply.time
            else:
                self.holding = False          # released, or refused because this session no longer held it
        return reply
