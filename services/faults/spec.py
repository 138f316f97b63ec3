"""Fault specifications: ``STREAM.KEY=VALUE`` strings → a validated :class:`FaultPlan` (pure).

Link streams (times in seconds from the run's t = 0, probabilities in [0, 1] or a percentage
such as ``50%``; every key may be given once, except the windows, which add up):

=============================  =================================================================
``S.delay_ms=300``             fixed one-way delay
``S.jitter_ms=50``             uniform jitter ±50 ms (netem's default shape)
``S.jitter=DIST:MS``           jitter with ``DIST`` one of ``uniform`` (±MS), ``normal`` (σ = MS)
                               or ``pareto`` (non-negative, heavy tail, mean MS)
``S.loss=0.5``                 Bernoulli loss
``S.burst=P,R``                Gilbert–Elliott burst loss (enter a burst with P, leave with R)
``S.blackout=START,DURATION``  nothing passes in [START, START+DURATION) (repeatable)
``S.duplicate=P``              a second copy with probability P
``S.reorder=P[,GAP_MS]``       held back GAP_MS (default 50) with probability P
``S.corrupt=P[,BITS]``         BITS (default 1) random bit flips with probability P
``S.rate=HZ[,QUEUE]``          at most HZ messages/s, tail drop behind QUEUE (default 1000)
``S.replay=P[,AGE_MS]``        a stale copy of a message AGE_MS (default 500) old, with probability P
=============================  =================================================================

``S`` is ``operator`` (console → controller: OperatorCommand, operator heartbeats),
``telemetry`` (controller → console: RobotState, Event, controller heartbeats) or ``can``
(both directions between the controller's and the robot's bus). CAN adds
``can.ids=feedback|command|all|0x0E[,0x2E…]`` (which frames the impairments touch; default
all), ``can.busoff=START,DURATION`` (the gateway forwards nothing: repeatable) and
``can.babble=HZ[,ID[,START,DURATION]]`` (a flood of ID, default 0x000, the highest priority,
at HZ ≤ 5000 frames/s on both buses; for the whole run unless a window is given).

Process faults: ``controller|console|robot.kill_at=SEC`` (SIGKILL), ``….stop_at=SEC,DURATION``
(SIGSTOP, SIGCONT DURATION later), ``controller.restart_at=SEC`` (a fresh controller, after a
kill), ``operator.estop_at=SEC`` (an operator's emergency stop, held down from SEC to the end of the
run: an OperatorCommand with ``estop`` set every 20 ms, as a console with its estop latched
sends, straight to the controller from a session of its own — the controller honours an estop
from anyone). SEC counts from the run's t = 0, the instant the operator was granted the
lease as the controller reports it. ``seed=N`` sets the seed (``--fault-seed`` otherwise; default 0).

Intruders and bad days (docs/security.md; the demo carries them out itself):

=======================================  =========================================================
``robot.reboot_at=SEC[,AXIS[,DOWN]]``    drive AXIS (default 1) of the simulated robot restarts:
                                         silent for DOWN s (default 0.5), then IDLE, no errors, its
                                         encoder counting from 0
``can.intruder_at=SEC[,HZ[,DURATION]]``  another CAN master: Set_Input_Torque 2 N·m to node 0 at HZ
                                         (default 200) for DURATION s (default 0.5) on the drives'
                                         bus (not with the other ``can.*`` faults: their gateway
                                         splits the bus)
``operator.flood_at=SEC[,HZ[,DURATION]]``  well-formed commands of a session that never held the lease,
                                         full deflection, at HZ (default 2000) for DURATION s (1)
``operator.evict_at=SEC``                200 sessions of one command each, then the lease holder's
                                         last command replayed as captured
``router.restart_at=SEC[,DOWN]``         the Zenoh router (``--secure``) killed and started again DOWN
                                         s (default 1) later on the same endpoint
=======================================  =========================================================

A bad spec raises :class:`FaultSpecError`, which names the key and the value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .impairments import (BernoulliLoss, Blackout, Corrupt, Delay, Duplicate, GilbertElliott, Pipeline, RateLimit,
                          Reorder, Replay, Stage)

LINKS = ("operator", "telemetry", "can")
PROCESSES = ("controller", "console", "robot")
INTRUSIONS = {   # (stream, key): (action, the parameters' names, their defaults after SEC)
    ("robot", "reboot_at"): ("reboot", "SEC[,AXIS[,DOWN]]", (1.0, 0.5)),
    ("can", "intruder_at"): ("intrude", "SEC[,HZ[,DURATION]]", (200.0, 0.5)),
    ("operator", "flood_at"): ("flood", "SEC[,HZ[,DURATION]]", (2000.0, 1.0)),
    ("operator", "evict_at"): ("evict", "SEC", ()),
    ("router", "restart_at"): ("bounce", "SEC[,DOWN]", (1.0,)),
}
MAX_INTRUSION_HZ = 5000.0
CAN_ID_CLASSES = ("feedback", "command", "all")
DEFAULT_REORDER_GAP_MS = 50.0
DEFAULT_REPLAY_AGE_MS = 500.0
DEFAULT_RATE_QUEUE = 1000
DEFAULT_BABBLE_ID = 0x000
MAX_BABBLE_HZ = 5000.0     # the gateway sends it at SCHED_FIFO on both buses: bounded so it cannot take a core


class FaultSpecError(ValueError):
    """A fault specification that cannot be used; names the offending key and value."""

    def __init__(self, spec: str, reason: str) -> None:
        super().__init__(f"bad fault {spec!r}: {reason}")
        self.spec, self.reason = spec, reason


@dataclass
class LinkFaults:
    """The impairments of one stream (all off by default)."""

    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    jitter_dist: str = "uniform"
    loss: float = 0.0
    burst: tuple[float, float] | None = None
    blackouts: list[tuple[float, float]] = field(default_factory=list)
    duplicate: float = 0.0
    reorder: tuple[float, float] | None = None        # (p, gap_ms)
    corrupt: tuple[float, int] | None = None          # (p, bits)
    rate: tuple[float, int] | None = None             # (hz, queue)
    replay: tuple[float, float] | None = None         # (p, age_ms)
    ids: tuple = ("all",)                             # CAN only: id classes or ids
    babble: tuple[float, int, float, float] | None = None   # CAN only: (hz, id, start, duration or inf)
    given: set = field(default_factory=set)

    @property
    def active(self) -> bool:
        return bool(self.given)


@dataclass(frozen=True)
class ProcessFault:
    target: str          # controller | console | robot | operator | can | router
    action: str          # kill | stop | restart | estop; reboot | intrude | flood | evict | bounce (INTRUSIONS)
    at: float            # s from the run's t = 0 (the lease instant)
    duration: float = 0.0
    params: tuple = ()   # an intrusion's numbers after SEC, defaults filled in (INTRUSIONS)

    def describe(self) -> str:
        for (target, key), (action, _, _) in INTRUSIONS.items():
            if (target, action) == (self.target, self.action):
                return f"{target}.{key}=" + ",".join(f"{v:g}" for v in (self.at, *self.params))
        return f"{self.target}.{self.action}_at={self.at:g}" + (f",{self.duration:g}" if self.action == "stop" else "")

    @property
    def hz(self) -> float:
        return self.params[0]


@dataclass
class FaultPlan:
    specs: list[str] = field(default_factory=list)
    seed: int = 0
    links: dict[str, LinkFaults] = field(default_factory=lambda: {name: LinkFaults() for name in LINKS})
    processes: list[ProcessFault] = field(default_factory=list)

    def has(self, link: str) -> bool:
        return self.links[link].active

    @property
    def empty(self) -> bool:
        return not self.specs


# ----- parsing -------------------------------------------------------------------
def _number(spec: str, text: str, what: str, low: float = 0.0, high: float = math.inf) -> float:
    try:
        value = float(text[:-1]) / 100.0 if text.endswith("%") else float(text)
    except ValueError:
        raise FaultSpecError(spec, f"{what} must be a number, got {text!r}") from None
    if not math.isfinite(value) or not low <= value <= high:
        raise FaultSpecError(spec, f"{what} must be in [{low:g}, {high:g}], got {text!r}")
    return value


def _prob(spec: str, text: str, what: str = "probability") -> float:
    return _number(spec, text, what, 0.0, 1.0)


def _parts(spec: str, value: str, least: int, most: int, form: str) -> list[str]:
    parts = [p.strip() for p in value.split(",")] if value else []
    if not least <= len(parts) <= most or any(not p for p in parts):
        raise FaultSpecError(spec, f"expected {form}")
    return parts


def _can_id(spec: str, text: str) -> int:
    try:
        value = int(text, 0)
    except ValueError:
        raise FaultSpecError(spec, f"CAN id must be an integer such as 0x2E, got {text!r}") from None
    if not 0 <= value <= 0x7FF:
        raise FaultSpecError(spec, f"CAN id {text!r} is not an 11-bit id")
    return value


def _window(spec: str, value: str) -> tuple[float, float]:
    start, duration = _parts(spec, value, 2, 2, "START,DURATION in seconds")
    return _number(spec, start, "START"), _number(spec, duration, "DURATION")


def _set_link(spec: str, link: LinkFaults, stream: str, key: str, value: str) -> None:
    if key in link.given and key not in ("blackout", "busoff"):
        raise FaultSpecError(spec, f"{stream}.{key} given twice")
    if key == "delay_ms":
        link.delay_ms = _number(spec, value, "delay_ms", 0.0, 60_000.0)
    elif key == "jitter_ms":
        link.jitter_ms, link.jitter_dist = _number(spec, value, "jitter_ms", 0.0, 60_000.0), "uniform"
    elif key == "jitter":
        dist, sep, ms = value.partition(":")
        if not sep or dist not in Delay.DISTRIBUTIONS:
            raise FaultSpecError(spec, f"expected DIST:MS with DIST one of {', '.join(Delay.DISTRIBUTIONS)}")
        link.jitter_ms, link.jitter_dist = _number(spec, ms, "jitter MS", 0.0, 60_000.0), dist
    elif key == "loss":
        link.loss = _prob(spec, value)
    elif key == "burst":
        p, r = _parts(spec, value, 2, 2, "P,R (enter and leave probabilities)")
        link.burst = (_prob(spec, p, "P"), _number(spec, r, "R", 1e-9, 1.0))
    elif key in ("blackout", "busoff"):
        if key == "busoff" and stream != "can":
            raise FaultSpecError(spec, "busoff is a CAN fault (use blackout for operator/telemetry)")
        link.blackouts.append(_window(spec, value))
    elif key == "duplicate":
        link.duplicate = _prob(spec, value)
    elif key == "reorder":
        parts = _parts(spec, value, 1, 2, "P[,GAP_MS]")
        link.reorder = (_prob(spec, parts[0]),
                        _number(spec, parts[1], "GAP_MS", 0.0, 60_000.0) if len(parts) > 1 else DEFAULT_REORDER_GAP_MS)
    elif key == "corrupt":
        parts = _parts(spec, value, 1, 2, "P[,BITS]")
        link.corrupt = (_prob(spec, parts[0]), int(_number(spec, parts[1], "BITS", 1, 512)) if len(parts) > 1 else 1)
    elif key == "rate":
        parts = _parts(spec, value, 1, 2, "HZ[,QUEUE]")
        link.rate = (_number(spec, parts[0], "HZ", 1e-3, 1e6),
                     int(_number(spec, parts[1], "QUEUE", 0, 1e6)) if len(parts) > 1 else DEFAULT_RATE_QUEUE)
    elif key == "replay":
        parts = _parts(spec, value, 1, 2, "P[,AGE_MS]")
        link.replay = (_prob(spec, parts[0]),
                       _number(spec, parts[1], "AGE_MS", 0.0, 600_000.0) if len(parts) > 1 else DEFAULT_REPLAY_AGE_MS)
    elif key == "ids" and stream == "can":
        parts = _parts(spec, value, 1, 64, "feedback|command|all or CAN ids such as 0x2E,0x4E")
        if len(parts) == 1 and parts[0] in CAN_ID_CLASSES:
            link.ids = (parts[0],)
        else:
            link.ids = tuple(_can_id(spec, p) for p in parts)
    elif key == "babble" and stream == "can":
        parts = _parts(spec, value, 1, 4, "HZ[,ID[,START,DURATION]]")
        if len(parts) == 3:
            raise FaultSpecError(spec, "a babble window needs both START and DURATION")
        hz = _number(spec, parts[0], "HZ", 1.0, MAX_BABBLE_HZ)
        can_id = _can_id(spec, parts[1]) if len(parts) > 1 else DEFAULT_BABBLE_ID
        start, duration = _window(spec, ",".join(parts[2:])) if len(parts) == 4 else (0.0, math.inf)
        link.babble = (hz, can_id, start, duration)
    else:
        known = "delay_ms, jitter_ms, jitter, loss, burst, blackout, duplicate, reorder, corrupt, rate, replay"
        known += ", ids, busoff, babble" if stream == "can" else ", estop_at" if stream == "operator" else ""
        raise FaultSpecError(spec, f"unknown key {stream}.{key} (known: {known})")
    link.given.add(key)


def _add_process(spec: str, plan: FaultPlan, target: str, key: str, value: str) -> None:
    actions = {"kill_at": "kill", "stop_at": "stop", "restart_at": "restart"}
    action = actions.get(key)
    if action is None or (action == "restart" and target != "controller"):
        allowed = "kill_at, stop_at" + (", restart_at" if target == "controller" else "")
        raise FaultSpecError(spec, f"unknown key {target}.{key} (known: {allowed})")
    if action == "stop":
        at, duration = _window(spec, value)
    else:
        at, duration = _number(spec, value, "SEC"), 0.0
    plan.processes.append(ProcessFault(target, action, at, duration))


def parse(specs: list[str], seed: int | None = None) -> FaultPlan:
    """Parse every ``--fault`` string; ``seed`` (``--fault-seed``) unless a ``seed=N`` spec overrides it."""
    plan = FaultPlan(specs=list(specs), seed=0 if seed is None else int(seed))
    for spec in specs:
        key, sep, value = (s.strip() for s in spec.partition("="))
        if not sep or not key or not value:
            raise FaultSpecError(spec, "expected KEY=VALUE, e.g. operator.delay_ms=300")
        if key == "seed":
            try:
                plan.seed = int(value, 0)
            except ValueError:
                raise FaultSpecError(spec, f"seed must be an integer, got {value!r}") from None
            continue
        target, dot, name = key.partition(".")
        if not dot or not name:
            raise FaultSpecError(spec, f"expected STREAM.KEY with STREAM one of {', '.join(LINKS + PROCESSES)}")
        if (target, name) in INTRUSIONS:
            plan.processes.append(_intrusion(spec, target, name, value))
        elif target == "operator" and name == "estop_at":
            plan.processes.append(ProcessFault("operator", "estop", _number(spec, value, "SEC")))
        elif target in LINKS:
            _set_link(spec, plan.links[target], target, name, value)
        elif target in PROCESSES:
            _add_process(spec, plan, target, name, value)
        else:
            raise FaultSpecError(spec, f"unknown stream {target!r} (known: {', '.join(LINKS + PROCESSES)})")
    _check_restarts(plan)
    if plan.has("can") and any(f.action == "intrude" for f in plan.processes):
        raise FaultSpecError("can.intruder_at", "the other can.* faults put a gateway between two buses; an "
                                                "intruder needs the one bus of the drives and the controller")
    plan.processes.sort(key=lambda f: f.at)
    return plan


def _intrusion(spec: str, target: str, name: str, value: str) -> ProcessFault:
    action, form, defaults = INTRUSIONS[(target, name)]
    parts = _parts(spec, value, 1, 1 + len(defaults), form)
    at = _number(spec, parts[0], "SEC")
    params = [_number(spec, p, form.split(",")[i + 1].strip("[]"), 0.0, MAX_INTRUSION_HZ)
              for i, p in enumerate(parts[1:])]
    params += list(defaults[len(params):])
    if action == "reboot":
        if params[0] not in (0.0, 1.0, 2.0) or not params[1] > 0:
            raise FaultSpecError(spec, "AXIS must be 0, 1 or 2 and DOWN positive")
        return ProcessFault(target, action, at, params[1], (params[0], params[1]))
    if action in ("intrude", "flood"):
        if not (params[0] >= 1.0 and params[1] > 0):
            raise FaultSpecError(spec, "HZ must be at least 1 and DURATION positive")
        return ProcessFault(target, action, at, params[1], tuple(params))
    if action == "bounce":
        if not params[0] > 0:
            raise FaultSpecError(spec, "DOWN must be positive")
        return ProcessFault(target, action, at, params[0], tuple(params))
    return ProcessFault(target, action, at)


def _check_restarts(plan: FaultPlan) -> None:
    kills = [f.at for f in plan.processes if f.target == "controller" and f.action == "kill"]
    for fault in plan.processes:
        if fault.action == "restart" and not any(k < fault.at for k in kills):
            raise FaultSpecError(fault.describe(), "restart_at needs an earlier controller.kill_at")


# ----- from a plan to a pipeline ------------------------------------------------
def stages(link: LinkFaults, corrupt_skip: int = 0) -> list[Stage]:
    """The impairment stages of one stream, in the order of services/faults/impairments.py."""
    out: list[Stage] = []
    if link.blackouts:
        out.append(Blackout(link.blackouts))
    if link.loss > 0:
        out.append(BernoulliLoss(link.loss))
    if link.burst is not None:
        out.append(GilbertElliott(*link.burst))
    if link.duplicate > 0:
        out.append(Duplicate(link.duplicate))
    if link.corrupt is not None:
        out.append(Corrupt(*link.corrupt, skip=corrupt_skip))
    if link.replay is not None:
        out.append(Replay(link.replay[0], link.replay[1] / 1000.0))
    if link.delay_ms > 0 or link.jitter_ms > 0:
        out.append(Delay(link.delay_ms / 1000.0, link.jitter_ms / 1000.0, link.jitter_dist))
    if link.reorder is not None:
        out.append(Reorder(link.reorder[0], link.reorder[1] / 1000.0))
    if link.rate is not None:
        out.append(RateLimit(*link.rate))
    return out


def pipeline(plan: FaultPlan, stream: str, corrupt_skip: int = 0) -> Pipeline:
    """The seeded pipeline of ``stream`` (``operator``, ``telemetry``, ``can.command``…): seed ``"<seed>:<stream>"``."""
    link = plan.links[stream.split(".")[0]]
    return Pipeline(stages(link, corrupt_skip), seed=f"{plan.seed}:{stream}")
