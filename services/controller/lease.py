"""The operator authority lease: which operator may command the robot. Pure: requests and times in, decisions out.

One operator session holds control at a time. A holder is an (operator_id, session_id) pair:
the session id is the console's random per-run token, so a second console of the same operator
id is a different requester.

* **take** — granted when nobody holds the lease, or to the holder itself (a renewal); refused
  while another session holds it (the decision names the holder).
* **release** — by the holder frees the lease; by anyone else it is refused.
* **expiry** — the holder renews the lease with every accepted command and every take; a lease
  not renewed for `expiry` seconds (1 s by default) is free again.
* **commands** — `admit_command` lets only the holder's commands through (reason `not_holder`
  otherwise). A command's own `control_request` is an in-band take or release.
* **before any lease** — mode `implicit` (the default, what a single-operator bench expects):
  a command while the lease is free takes it for its session, first come first served, except
  from a session that released the lease explicitly (it must take again). Mode `explicit` (for
  sites): only a take grants the lease, commands from a session without it are refused
  (`no_lease`).

Emergency stops are not the lease's business: the caller honours an estop from every
well-formed command, holder or not.
"""
from __future__ import annotations

import enum
from collections import OrderedDict
from dataclasses import dataclass

from sharedctl.protocol.messages import ControlRequest, LeaseAction

DEFAULT_EXPIRY = 1.0      # s without renewal before the lease is free again
MAX_RELEASED = 64         # sessions remembered as having released the lease (implicit mode)


class LeaseMode(enum.StrEnum):
    """How control is first obtained."""

    IMPLICIT = "implicit"     # a command while the lease is free takes it
    EXPLICIT = "explicit"     # only a take (query or in-band) grants the lease


@dataclass(frozen=True)
class Holder:
    operator_id: str
    session_id: str
    since: float              # s, controller clock, when the lease was granted


@dataclass(frozen=True)
class LeaseDecision:
    """The answer to a take or release."""

    granted: bool
    holder: str | None        # operator id holding control after the request
    reason: str


@dataclass(frozen=True)
class LeaseChange:
    """A change of holder, for events: `before`/`after` operator ids, `cause` taken|released|expired."""

    time: float
    before: str | None
    after: str | None
    cause: str


class OperatorLease:
    """The lease state machine; every method takes the caller's time `now` (s, monotonic)."""

    def __init__(self, expiry: float = DEFAULT_EXPIRY, mode: LeaseMode | str = LeaseMode.IMPLICIT) -> None:
        if not expiry > 0:
            raise ValueError("lease expiry must be positive")
        self.expiry = float(expiry)
        self.mode = LeaseMode(mode)
        self.holder: Holder | None = None
        self.renewed_at = 0.0
        self.grants = 0
        self.expirations = 0
        self._changes: list[LeaseChange] = []
        self._released: OrderedDict = OrderedDict()   # sessions that released (implicit mode)

    # ------------------------------------------------------------------ state
    def update(self, now: float) -> None:
        """Expire the lease if its holder has not renewed it within `expiry` seconds."""
        if self.holder is not None and now - self.renewed_at > self.expiry:
            self._set(None, now, "expired")
            self.expirations += 1

    def holds(self, operator_id: str, session_id: str, now: float) -> bool:
        self.update(now)
        return (self.holder is not None
                and (self.holder.operator_id, self.holder.session_id) == (operator_id, session_id))

    @property
    def holder_id(self) -> str | None:
        return None if self.holder is None else self.holder.operator_id

    @property
    def holder_since(self) -> float | None:
        """When the holder was granted the lease (the caller's clock; renewals keep it), None while free."""
        return None if self.holder is None else self.holder.since

    def take_changes(self) -> list[LeaseChange]:
        """Changes of holder since the last call (oldest first)."""
        changes, self._changes = self._changes, []
        return changes

    # --------------------------------------------------------------- requests
    def request(self, operator_id: str, session_id: str, action: LeaseAction, now: float) -> LeaseDecision:
        """A take or release (the queryable's request, or a command's control_request)."""
        self.update(now)
        mine = self.holds(operator_id, session_id, now)
        if LeaseAction(action) is LeaseAction.TAKE:
            if mine:
                self.renewed_at = now
                return LeaseDecision(True, operator_id, "renewed")
            if self.holder is not None:
                return LeaseDecision(False, self.holder.operator_id,
                                     f"control is held by {self.holder.operator_id}")
            self._released.pop(session_id, None)
            self._grant(operator_id, session_id, now)
            return LeaseDecision(True, operator_id, "granted")
        if not mine:
            return LeaseDecision(False, self.holder_id,
                                 "not the holder" if self.holder is not None else "nobody holds control")
        self._set(None, now, "released")
        self._released[session_id] = True
        while len(self._released) > MAX_RELEASED:
            self._released.popitem(last=False)
        return LeaseDecision(True, None, "released")

    def admit_command(self, operator_id: str, session_id: str, control_request: ControlRequest,
                      now: float) -> str | None:
        """None if a command of this session may drive (the lease is renewed), else why not.

        Reasons: `not_holder` (another session holds the lease), `no_lease` (nobody holds it and
        this command cannot take it), `released` (the command released the lease)."""
        request = ControlRequest(control_request)
        if request is ControlRequest.TAKE:
            decision = self.request(operator_id, session_id, LeaseAction.TAKE, now)
            return None if decision.granted else "not_holder"
        if request is ControlRequest.RELEASE:
            decision = self.request(operator_id, session_id, LeaseAction.RELEASE, now)
            return "released" if decision.granted else ("not_holder" if self.holder is not None else "no_lease")
        if self.holds(operator_id, session_id, now):
            self.renewed_at = now
            return None
        if self.holder is not None:
            return "not_holder"
        if self.mode is LeaseMode.IMPLICIT and session_id not in self._released:
            self._grant(operator_id, session_id, now)
            return None
        return "no_lease"

    # -------------------------------------------------------------- internals
    def _grant(self, operator_id: str, session_id: str, now: float) -> None:
        self._set(Holder(operator_id, session_id, now), now, "taken")
        self.renewed_at = now
        self.grants += 1

    def _set(self, holder: Holder | None, now: float, cause: str) -> None:
        before = self.holder_id
        self.holder = holder
        self._changes.append(LeaseChange(now, before, self.holder_id, cause))
        del self._changes[:-16]     # bounded if nobody drains them
