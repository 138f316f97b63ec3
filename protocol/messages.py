"""Typed messages carried over Zenoh (MessagePack-encoded by :mod:`.msgpack_codec`).

Every message is a frozen dataclass whose constructor validates and normalises
each field (floats finite and bounded, arrays as tuples of the right length,
enums as members, identifiers as tokens). Field names are the MessagePack map
keys. Units are SI unless the name says otherwise (``*_ms`` milliseconds);
generalised coordinates follow the control core (``q`` = x [m], y [m], yaw [rad]
for this project's robot).

Array lengths: every ``dof`` array of one message has the same length n
(1..8); ``theta_hat`` has n_theta (0..16) entries; ``wheel_torques`` n_wheels
(1..8). The decoder also checks them against the receiver's :class:`Dims`.
"""
from __future__ import annotations

import enum
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, ClassVar

from .errors import MissingField, OutOfRange, WrongLength, WrongType
from .wire_types import (
    MAX_GROUPS,
    MAX_REGIONS,
    MAX_THETA,
    MAX_WHEELS,
    Check,
    Dims,
    boolean,
    choice,
    index,
    optional,
    real,
    sequence,
    text,
    token,
    uint64,
    vector,
)

WIRE_VERSION: tuple[int, int] = (1, 2)
"""(major, minor) written by this implementation; see protocol/README.md, "Versioning"."""


class SetClass(enum.StrEnum):
    """Classification of the state with respect to one constraint group."""

    SAFE = "safe"
    HYSTERESIS = "hysteresis"
    HAZARD = "hazard"


class Authority(enum.StrEnum):
    """Who drives the robot: the operator alone, a blend, or the machine alone."""

    HUMAN = "human"
    SHARED = "shared"
    MACHINE = "machine"


class ControlRequest(enum.StrEnum):
    """Lease request carried by an operator command."""

    NONE = "none"
    TAKE = "take"
    RELEASE = "release"


class LeaseAction(enum.StrEnum):
    """Action of a lease query on ``.../control/lease``."""

    TAKE = "take"
    RELEASE = "release"


class EventKind(enum.StrEnum):
    """What happened."""

    ESTOP = "estop"
    ESTOP_CLEARED = "estop_cleared"
    WATCHDOG_TRIP = "watchdog_trip"
    FAULT = "fault"
    FAULT_CLEARED = "fault_cleared"
    REJECTION = "rejection"
    AUTHORITY_CHANGE = "authority_change"
    LEASE_CHANGE = "lease_change"
    SET_TRANSITION = "set_transition"
    INFO = "info"


class Severity(enum.StrEnum):
    """How much it matters."""

    DEBUG = "debug"
    INFO = "info"
    WARNING = "warning"
    ERROR = "error"
    CRITICAL = "critical"


def wire(check: Check, dim: str | None = None, default: Any = MISSING) -> Any:
    """Declare a wire field: its validator and, for arrays, the dimension it follows.

    A field added by a minor version has a ``default``: a payload of an older minor that
    lacks it decodes with that value (protocol/README.md §2.2)."""
    return field(default=default, metadata={"check": check, "dim": dim})


def _validate(obj: Any) -> None:
    lengths: dict[str, int] = {}
    for name, check, dim in type(obj).WIRE_FIELDS:
        value = check(getattr(obj, name), name)
        object.__setattr__(obj, name, value)
        if dim is None:
            continue
        if dim in lengths and lengths[dim] != len(value):
            raise WrongLength(f"{name} has {len(value)} entries, other {dim} arrays {lengths[dim]}")
        lengths[dim] = len(value)
    if lengths.get("dof", 1) == 0 or lengths.get("n_wheels", 1) == 0:
        raise WrongLength("dof and wheel arrays need at least one entry")


def wire_message(kind: str | None, max_bytes: int = 0):
    """Class decorator: frozen slotted dataclass with validating ``__post_init__``.

    ``kind`` is the payload's kind tag (``None`` for nested records) and
    ``max_bytes`` the bound on its encoded size.
    """

    def wrap(cls: type) -> type:
        user_check = cls.__dict__.get("_check", None)

        def __post_init__(self: Any) -> None:
            _validate(self)
            if user_check is not None:
                user_check(self)

        cls.__post_init__ = __post_init__
        cls = dataclass(frozen=True, slots=True)(cls)
        cls.WIRE_FIELDS = tuple((f.name, f.metadata["check"], f.metadata["dim"]) for f in fields(cls))
        cls.WIRE_DEFAULTS = {f.name: f.default for f in fields(cls) if f.default is not MISSING}
        cls.KIND = kind
        cls.MAX_BYTES = max_bytes
        return cls

    return wrap


def nested(record_cls: type) -> Check:
    """A nested record (a map on the wire); unknown keys are ignored, missing ones refused."""

    def check(value: Any, what: str) -> Any:
        if isinstance(value, record_cls):
            return value
        if not isinstance(value, dict):
            raise WrongType(f"{what} must be a map")
        defaults = record_cls.WIRE_DEFAULTS
        missing = [name for name, _, _ in record_cls.WIRE_FIELDS if name not in value and name not in defaults]
        if missing:
            raise MissingField(f"{what}.{missing[0]} is missing")
        return record_cls(**{name: value.get(name, defaults.get(name)) for name, _, _ in record_cls.WIRE_FIELDS})

    return check


_time = real(0.0)
_vec = vector()


@wire_message("operator_command", max_bytes=2048)
class OperatorCommand:
    """Operator -> controller at the teleoperation rate (``.../operator/cmd``)."""

    WIRE_FIELDS: ClassVar[tuple]
    operator_id: str = wire(token)
    session_id: str = wire(token)
    seq: int = wire(uint64)
    send_time: float = wire(_time)                    # s, sender clock
    joystick: tuple[float, ...] = wire(vector(-1.0, 1.0), "dof")  # normalised deflection
    q_d: tuple[float, ...] = wire(_vec, "dof")        # desired pose
    qd_d: tuple[float, ...] = wire(_vec, "dof")       # desired velocity
    qdd_d: tuple[float, ...] = wire(_vec, "dof")      # desired acceleration
    deadman: bool = wire(boolean)                     # True while the enabling switch is held
    estop: bool = wire(boolean)                       # True requests an emergency stop
    control_request: ControlRequest = wire(choice(ControlRequest))


@wire_message(None)
class LinkHealth:
    """Link quality as seen by the controller (nested in :class:`RobotState`)."""

    WIRE_FIELDS: ClassVar[tuple]
    operator_latency_ms: float = wire(real(0.0))
    loss_fraction: float = wire(real(0.0, 1.0))
    staleness_ms: float = wire(real(0.0))
    can_feedback_age_ms: float = wire(real(0.0))
    rejected_messages: int = wire(uint64, default=0)   # since 1.1: operator messages the controller refused


@wire_message("robot_state", max_bytes=4096)
class RobotState:
    """Controller -> console/operator telemetry (``.../state``)."""

    WIRE_FIELDS: ClassVar[tuple]
    seq: int = wire(uint64)
    time: float = wire(_time)                         # s, controller clock
    q: tuple[float, ...] = wire(_vec, "dof")          # estimated pose
    qd_hat: tuple[float, ...] = wire(_vec, "dof")     # estimated velocity
    q_ref: tuple[float, ...] = wire(_vec, "dof")      # projected reference
    group_classes: tuple[SetClass, ...] = wire(sequence(choice(SetClass), MAX_GROUPS))
    active_group: int | None = wire(optional(index))  # index into group_classes, or None
    authority: Authority = wire(choice(Authority))
    k_s: float = wire(real(0.0, 1.0))
    k_h: float = wire(real(0.0, 1.0))
    k_f: float = wire(real(0.0, 1.0))
    u_h: tuple[float, ...] = wire(_vec, "dof")        # operator's command
    u_f: tuple[float, ...] = wire(_vec, "dof")        # machine (safety) command
    u_s: tuple[float, ...] = wire(_vec, "dof")        # shared command applied
    wheel_torques: tuple[float, ...] = wire(vector(max_len=MAX_WHEELS), "n_wheels")  # Nm
    theta_hat: tuple[float, ...] = wire(vector(max_len=MAX_THETA), "n_theta")
    min_margin: float = wire(real())
    region_margins: tuple[float, ...] = wire(vector(max_len=MAX_REGIONS))
    estop_active: bool = wire(boolean)
    lease_holder: str | None = wire(optional(token))  # operator id holding control, or None
    link: LinkHealth = wire(nested(LinkHealth))
    lease_since: float | None = wire(optional(_time), default=None)  # since 1.2: s, controller clock, when
    #                                                   the holder was granted control (None while free)

    def _check(self) -> None:
        if self.active_group is not None and self.active_group >= len(self.group_classes):
            raise OutOfRange(f"active_group {self.active_group} but {len(self.group_classes)} groups")


@wire_message("event", max_bytes=3072)
class Event:
    """Something worth logging or showing (``.../events``)."""

    WIRE_FIELDS: ClassVar[tuple]
    seq: int = wire(uint64)
    time: float = wire(_time)
    kind: EventKind = wire(choice(EventKind))
    severity: Severity = wire(choice(Severity))
    source: str = wire(token)                         # role or id of the emitter
    text: str = wire(text())                          # at most 256 characters


@wire_message("heartbeat", max_bytes=512)
class Heartbeat:
    """Liveliness of one process (``.../alive/<role>``)."""

    WIRE_FIELDS: ClassVar[tuple]
    role: str = wire(token)
    id: str = wire(token)
    seq: int = wire(uint64)
    time: float = wire(_time)


@wire_message("lease_request", max_bytes=512)
class LeaseRequest:
    """Query payload on ``.../control/lease``: take or release control."""

    WIRE_FIELDS: ClassVar[tuple]
    operator_id: str = wire(token)
    session_id: str = wire(token)
    seq: int = wire(uint64)
    time: float = wire(_time)
    action: LeaseAction = wire(choice(LeaseAction))


@wire_message("lease_reply", max_bytes=3072)
class LeaseReply:
    """Reply to a :class:`LeaseRequest`."""

    WIRE_FIELDS: ClassVar[tuple]
    request_seq: int = wire(uint64)                   # seq of the request answered
    time: float = wire(_time)
    granted: bool = wire(boolean)
    holder: str | None = wire(optional(token))        # operator holding control after the request
    reason: str = wire(text())


@wire_message("ground_truth", max_bytes=512)
class GroundTruth:
    """Simulator ground truth for evaluation only (``.../truth``); never used for control."""

    WIRE_FIELDS: ClassVar[tuple]
    seq: int = wire(uint64)
    time: float = wire(_time)
    q: tuple[float, ...] = wire(_vec, "dof")
    qd: tuple[float, ...] = wire(_vec, "dof")


Message = OperatorCommand | RobotState | Event | Heartbeat | LeaseRequest | LeaseReply | GroundTruth
MESSAGE_TYPES: tuple[type, ...] = (
    OperatorCommand, RobotState, Event, Heartbeat, LeaseRequest, LeaseReply, GroundTruth)
KIND_TO_TYPE: dict[str, type] = {cls.KIND: cls for cls in MESSAGE_TYPES}


def shape_of(message: Any) -> dict[str, int]:
    """The array dimensions a message carries, e.g. ``{"dof": 3, "n_theta": 3, "n_wheels": 3}``."""
    return {dim: len(getattr(message, name)) for name, _, dim in message.WIRE_FIELDS if dim}


def check_dims(message: Any, dims: Dims) -> None:
    """Raise :class:`WrongLength` unless the message's arrays have the lengths of ``dims``."""
    for dim, length in shape_of(message).items():
        expected = getattr(dims, dim)
        if length != expected:
            raise WrongLength(f"{type(message).__name__} has {dim}={length}, expected {expected}")
