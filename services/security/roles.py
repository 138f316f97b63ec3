"""Who may do what on the Zenoh keys of sharedctl: the roles and the router's access-control list.

Pure data (no zenoh import): `access_control()` returns the `access_control` section of a
router configuration. Every role authenticates (a usrpwd user named after the role, or, under
mutual TLS, a client certificate whose common name is the role) and the router's default is
**deny**. What a role may *write* (what the router accepts from it, flow `ingress`):

    operator    put  …/operator/cmd and …/alive/operator; query …/control/lease (take/release);
                its liveliness token …/alive/operator
    controller  put  …/state, …/events, …/alive/controller; declare the …/control/lease
                queryable and reply on it; its liveliness token …/alive/controller
    robot       put  …/truth and …/alive/robot; its liveliness token …/alive/robot
    observer    nothing: subscribes only

What every authenticated role may *read*: declare subscribers (and liveliness subscribers and
queries) on `sharedctl/**`, and receive liveliness tokens and declarations there and the
publications of state, events, heartbeats and ground truth (flow `egress` for deliveries).
Operator commands are delivered only to the controller and to observers (recorders): an operator
never sees another operator's commands, so it cannot learn the session id it would need to pass
for that operator (every operator shares the role's credentials; the controller's lease and
replay guard key on operator and session id). Deliveries of a query go only to the controller
(the lease's queryable) and replies only to the operator. Keys are matched with `*` in the robot-id chunk, so
one router serves several robots with the same rules. A message nobody allowed is dropped by the
router without an error at the sender (Zenoh's ACL gives no feedback; the router logs it at
debug level).

**Operators by name.** `access_control(operators={"alice": ("robot1",), "bob": ("*",)})` gives each
operator its own subject (user name and certificate common name = the operator's name) and its
own policy: the operator role's rules with the robot-id chunk replaced by the robots it may
command (`*` for every one). alice's credentials then cannot put a command or ask for the lease of
robot2 at the router, whatever the controller does. Without `operators` there is one operator
subject named `operator` for every robot (`{"operator": ("*",)}`).
"""
from __future__ import annotations

import re

ROLES = ("operator", "controller", "robot", "observer")
PREFIX = "sharedctl/v1/*"
ALL_KEYS = "sharedctl/**"

_ROLE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")


class RoleError(ValueError):
    """An unknown role or a role name that is not a token."""


def check_role_name(role: object) -> str:
    if not isinstance(role, str) or not _ROLE_NAME.match(role):
        raise RoleError(f"role {role!r}: 1..64 letters, digits, '_' or '-'")
    return role


ANY_ROBOT = "*"
RESERVED_NAMES = ("router", "ca")     # file names the credentials directory uses for itself


def check_operators(operators: dict, roles=ROLES) -> dict[str, tuple[str, ...]]:
    """{operator name: robots} with tokens only: a name that is not another role's or reserved, robots that are
    robot ids or `*`; raises RoleError."""
    checked: dict[str, tuple[str, ...]] = {}
    for name, robots in operators.items():
        check_role_name(name)
        if (name in roles and name != "operator") or name in RESERVED_NAMES:
            raise RoleError(f"operator name {name!r} is taken by a role or a file of the site")
        robots = tuple(robots)
        if not robots:
            raise RoleError(f"operator {name!r}: no robots (give robot ids, or * for every robot)")
        for robot in robots:
            if robot != ANY_ROBOT:
                check_role_name(robot)
        checked[name] = robots
    return checked


# role -> {message kind: key expressions it may send (flow ingress at the router)}
WRITES: dict[str, dict[str, tuple[str, ...]]] = {
    "operator": {
        "put": (f"{PREFIX}/operator/cmd", f"{PREFIX}/alive/operator"),
        "query": (f"{PREFIX}/control/lease",),
        "liveliness_token": (f"{PREFIX}/alive/operator",),
    },
    "controller": {
        "put": (f"{PREFIX}/state", f"{PREFIX}/events", f"{PREFIX}/alive/controller"),
        "declare_queryable": (f"{PREFIX}/control/lease",),
        "reply": (f"{PREFIX}/control/lease",),
        "liveliness_token": (f"{PREFIX}/alive/controller",),
    },
    "robot": {
        "put": (f"{PREFIX}/truth", f"{PREFIX}/alive/robot"),
        "liveliness_token": (f"{PREFIX}/alive/robot",),
    },
    "observer": {},
}

# role -> {message kind: key expressions delivered to it (flow egress) beyond the common reads}
DELIVERIES: dict[str, dict[str, tuple[str, ...]]] = {
    "operator": {"reply": (f"{PREFIX}/control/lease",)},
    "controller": {"query": (f"{PREFIX}/control/lease",), "put": (f"{PREFIX}/operator/cmd",)},
    "robot": {},
    "observer": {"put": (f"{PREFIX}/operator/cmd",)},
}

READ_INGRESS = ("declare_subscriber", "declare_liveliness_subscriber", "liveliness_query")
READ_EGRESS = ("liveliness_token", "declare_subscriber", "declare_queryable")
# publications every role receives: everything but operator commands (Zenoh's ACL has no "except")
READ_PUTS = (f"{PREFIX}/state", f"{PREFIX}/events", f"{PREFIX}/alive/*", f"{PREFIX}/truth")


def _rule(rule_id: str, flow: str, messages, key_exprs) -> dict:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": list(messages),
            "key_exprs": list(key_exprs)}


def _for_robots(key_exprs, robots) -> list[str]:
    """The role's key expressions with the robot-id chunk `*` replaced by each of `robots`."""
    if tuple(robots) == (ANY_ROBOT,):
        return list(key_exprs)
    return [key.replace(PREFIX, f"sharedctl/v1/{robot}", 1) for key in key_exprs for robot in robots]


def rules_for(role: str, name: str | None = None, robots=(ANY_ROBOT,)) -> list[dict]:
    """The allow rules of one role (ids `NAME-write-KIND`, `NAME-deliver-KIND`; NAME = the role unless given), for
    the keys of `robots` (default every robot)."""
    if role not in WRITES:
        raise RoleError(f"unknown role {role!r} (one of {', '.join(ROLES)})")
    name = name or role
    rules = [_rule(f"{name}-write-{kind}", "ingress", [kind], _for_robots(keys, robots))
             for kind, keys in WRITES[role].items()]
    rules += [_rule(f"{name}-deliver-{kind}", "egress", [kind], _for_robots(keys, robots))
              for kind, keys in DELIVERIES[role].items()]
    return rules


def subject(name: str, tls: bool, usrpwd: bool) -> dict:
    """How the router recognises a role or a named operator: its username and/or (mTLS) its certificate's common
    name."""
    entry: dict = {"id": f"{name}-subject"}
    if usrpwd:
        entry["usernames"] = [name]
    if tls:
        entry["cert_common_names"] = [name]
    if len(entry) == 1:
        raise RoleError("a subject needs usernames (usrpwd) or certificate common names (mTLS)")
    return entry


def principals(roles=ROLES, operators: dict | None = None) -> dict[str, tuple[str, tuple[str, ...]]]:
    """{user name: (role, robots)}: every role but the operator under its own name for every robot, and each
    operator under its name for its robots (default: one operator named `operator`, every robot)."""
    roles = [check_role_name(r) for r in roles]
    if operators is None:
        operators = {"operator": (ANY_ROBOT,)} if "operator" in roles else {}
    operators = check_operators(operators, roles)
    named: dict[str, tuple[str, tuple[str, ...]]] = {}
    for role in roles:
        if role == "operator":
            named.update({name: ("operator", robots) for name, robots in operators.items()})
        else:
            named[role] = (role, (ANY_ROBOT,))
    if "operator" not in roles:
        named.update({name: ("operator", robots) for name, robots in operators.items()})
    return named


def access_control(roles=ROLES, tls: bool = False, usrpwd: bool = True, operators: dict | None = None) -> dict:
    """The router's `access_control` section: default deny, the rules above for each role, one subject and policy
    per named operator (`principals`).

    With both `tls` and `usrpwd`, a subject matches only a connection that presents both the
    role's certificate and the role's password (Zenoh takes the product of the lists)."""
    read = [_rule("read-declare", "ingress", READ_INGRESS, [ALL_KEYS]),
            _rule("read-deliver", "egress", READ_EGRESS, [ALL_KEYS]),
            _rule("read-deliver-put", "egress", ["put"], READ_PUTS)]
    rules = list(read)
    policies = []
    subjects = []
    for name, (role, robots) in principals(roles, operators).items():
        own = rules_for(role, name, robots)
        rules += own
        subjects.append(subject(name, tls, usrpwd))
        policies.append({"id": f"{name}-policy", "rules": [r["id"] for r in read + own],
                         "subjects": [f"{name}-subject"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}
