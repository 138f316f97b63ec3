"""Zenoh key expressions of sharedctl (layout v1). Pure strings; no zenoh import.

Layout (robot id before the kind; the ``v1`` segment is the wire major version,
so peers of different majors never see each other's traffic)::

    sharedctl/v1/<robot>/operator/cmd       OperatorCommand     operator -> controller
    sharedctl/v1/<robot>/state              RobotState          controller -> console, operator
    sharedctl/v1/<robot>/events             Event               any -> console, logger
    sharedctl/v1/<robot>/alive/<role>       Heartbeat           every process
    sharedctl/v1/<robot>/truth              GroundTruth         simulator -> evaluation only
    sharedctl/v1/<robot>/control/lease      LeaseRequest query  operator -> controller (LeaseReply)

Robot ids and roles are tokens: 1..64 ASCII letters, digits, ``_`` or ``-``,
starting with a letter or digit, so no wildcard (``*``, ``**``), verbatim
(``$``), ``#``, ``?`` or ``/`` can appear inside a chunk.
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import KeyExprError
from .messages import WIRE_VERSION
from .wire_types import MAX_TOKEN_LEN, check_token

ROOT = "sharedctl"
LAYOUT = f"v{WIRE_VERSION[0]}"
PREFIX = f"{ROOT}/{LAYOUT}"
MAX_KEY_LEN = len(PREFIX) + 2 * (MAX_TOKEN_LEN + 1) + len("/control/lease")

# kind name -> trailing chunks after the robot id ("<role>" marks the role chunk)
KINDS: dict[str, tuple[str, ...]] = {
    "operator_cmd": ("operator", "cmd"),
    "state": ("state",),
    "events": ("events",),
    "alive": ("alive", "<role>"),
    "truth": ("truth",),
    "lease": ("control", "lease"),
}


def check_robot_id(robot: object) -> str:
    """Return ``robot`` if it is a valid robot id, else raise :class:`KeyExprError`."""
    return check_token(robot, "robot id", KeyExprError) if isinstance(robot, str) else _not_str("robot id")


def check_role(role: object) -> str:
    """Return ``role`` if it is a valid role (e.g. ``operator``, ``controller``), else raise."""
    return check_token(role, "role", KeyExprError) if isinstance(role, str) else _not_str("role")


def _not_str(what: str) -> str:
    raise KeyExprError(f"{what} must be a string")


def operator_cmd_key(robot: str) -> str:
    """``sharedctl/v1/<robot>/operator/cmd``."""
    return f"{PREFIX}/{check_robot_id(robot)}/operator/cmd"


def state_key(robot: str) -> str:
    """``sharedctl/v1/<robot>/state``."""
    return f"{PREFIX}/{check_robot_id(robot)}/state"


def events_key(robot: str) -> str:
    """``sharedctl/v1/<robot>/events``."""
    return f"{PREFIX}/{check_robot_id(robot)}/events"


def alive_key(robot: str, role: str) -> str:
    """``sharedctl/v1/<robot>/alive/<role>``."""
    return f"{PREFIX}/{check_robot_id(robot)}/alive/{check_role(role)}"


def alive_pattern(robot: str) -> str:
    """Subscription pattern for every role's heartbeat: ``sharedctl/v1/<robot>/alive/*``."""
    return f"{PREFIX}/{check_robot_id(robot)}/alive/*"


def truth_key(robot: str) -> str:
    """``sharedctl/v1/<robot>/truth`` (simulator ground truth; evaluation only)."""
    return f"{PREFIX}/{check_robot_id(robot)}/truth"


def lease_key(robot: str) -> str:
    """``sharedctl/v1/<robot>/control/lease`` (queryable: take / release control)."""
    return f"{PREFIX}/{check_robot_id(robot)}/control/lease"


def robot_pattern(robot: str) -> str:
    """Everything about one robot: ``sharedctl/v1/<robot>/**`` (recorders, consoles)."""
    return f"{PREFIX}/{check_robot_id(robot)}/**"


@dataclass(frozen=True, slots=True)
class ParsedKey:
    """A concrete sharedctl key split into its parts; ``role`` only for ``alive``."""

    robot: str
    kind: str
    role: str | None = None


def parse_key(key: object) -> ParsedKey:
    """Split a concrete key (no wildcards) into robot, kind and role, or raise :class:`KeyExprError`."""
    if not isinstance(key, str):
        raise KeyExprError("key must be a string")
    if len(key) > MAX_KEY_LEN:
        raise KeyExprError("key too long")
    chunks = key.split("/")
    if len(chunks) < 4 or chunks[0] != ROOT:
        raise KeyExprError("not a sharedctl key")
    if chunks[1] != LAYOUT:
        raise KeyExprError(f"key layout {chunks[1][:16]!r} is not {LAYOUT}")
    robot = check_robot_id(chunks[2])
    tail = tuple(chunks[3:])
    for kind, pattern in KINDS.items():
        if len(pattern) != len(tail):
            continue
        if all(p == t for p, t in zip(pattern, tail) if p != "<role>"):
            role = check_role(tail[-1]) if pattern[-1] == "<role>" else None
            return ParsedKey(robot, kind, role)
    raise KeyExprError("unknown sharedctl key kind")
