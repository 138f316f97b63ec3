"""The fault side of `sharedctl demo --fault SPEC`: wiring, process faults, counters, judgement.

The demo (`services/demo/command.py`) calls this module in a few places; with no ``--fault`` nothing here runs and
the demo is exactly the unimpaired one.

* ``operator.*``/``telemetry.*`` faults: a `sharedctl fault-relay` child listens on its own
  loopback port F and connects to the controller's endpoint C; the console connects to F
  instead of C. The demo's own measuring session still connects to C and R directly. Behind
  ``--secure`` the relay listens nowhere: it is a client of the console's own router and of
  the site router (security/secure_stack.py, `relay_args`), and says it is up in a ready file.
* ``can.*`` faults: the controller and the robot get two different host-local udp_multicast
  ports and a `sharedctl fault-gateway` child forwards between them.
* process faults (``controller|console|robot.kill_at`` / ``stop_at``, ``controller.restart_at``)
  are carried out by the demo's supervision loop, by PID, only on the demo's own children; a
  stopped child is always continued (SIGCONT) before the demo stops it. ``operator.estop_at``
  is an estop button held down: from SEC to the end of the run the demo's own session sends the
  controller an OperatorCommand with ``estop`` set every ESTOP_PERIOD, as the console does while its
  estop is latched — so a controller (re)started after SEC, or one that lost a command, still gets it.
* intruders and bad days (spec.py, INTRUSIONS), carried out by the demo itself, each on a
  thread of its own so that the supervision loop keeps its times: ``robot.reboot_at`` is SIGUSR2
  to the robot (started with ``--drive-restart AXIS,DOWN``); ``can.intruder_at`` sends
  Set_Input_Torque frames from a CAN transport of the demo's own on the drives' bus;
  ``operator.flood_at`` and ``operator.evict_at`` publish on the demo's operator-capable session
  (evict replays the last command of the lease holder it heard, after 200 one-command sessions);
  ``router.restart_at`` kills the ``--secure`` router and starts it again on its endpoint.

The run's clock: t = 0 is the instant the operator was granted the lease, as the controller
reports it (``RobotState.lease_since``, wire 1.2) — not when the demo's session first heard of
it, one telemetry period or more later. Every timed fault is due at its SEC on that clock; the
supervision loop sleeps until the next one is due (never longer than its 50 ms poll), so a fault
fires within SCHEDULING_TOLERANCE of its time unless the demo learnt t = 0 only after it. The
instant each one actually fired (at the signal or the put, on the run's clock) is reported as
``done_at`` with ``late_by`` = done_at − SEC. The relay and gateway forward unimpaired until the
demo sends them SIGUSR1; before it, the demo writes t = 0 (wall clock) to their origin file, so
their windows (blackouts, bus-off) open on the same clock.

How a run with intended faults is judged (``ok``): the run started (the operator got control,
and no emergency stop came before the faults were armed), the simulator's ground truth shows
0 violations and was recorded, the relay/gateway stayed up and exited cleanly, and every
process that was not deliberately killed exited cleanly (exit 0 on SIGTERM). An emergency
stop during the run is the safety policy answering a fault: reported (``estops``), not a
failure. A killed child's non-zero exit is an intended outcome. The reasons against ``ok``
are listed in ``injected.not_ok``.
"""
from __future__ import annotations

import json
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..children import raise_priority
from .spec import FaultPlan, ProcessFault, parse

READY_TIMEOUT = 15.0
POLL = 0.05                    # s, the supervision loop's period when no fault is due sooner
SCHEDULING_TOLERANCE = 0.005   # s a fault may fire after its time (the demo's wake-up and the signal/put)
ESTOP_OPERATOR = "fault-estop"  # operator id of the injected estop commands
ESTOP_PERIOD = 0.02            # s between the held estop's commands (the console's command period)
INTRUDER_NODE, INTRUDER_TORQUE = 0, 2.0   # what another CAN master asks for (N·m to node 0)
EVICTING_SESSIONS = 200                   # one-command sessions sent before the captured command is replayed


def add_arguments(p) -> None:
    p.add_argument("--fault", action="append", default=[], metavar="SPEC",
                   help="inject a fault, e.g. operator.delay_ms=300, can.loss=0.05, controller.kill_at=5 (repeatable)")
    p.add_argument("--fault-seed", type=int, default=None, metavar="N",
                   help="seed of the injected impairments (default 0)")


@dataclass
class Injection:
    """One process fault as carried out."""

    fault: ProcessFault
    done_at: float | None = None       # s on the run's clock: when the signal (or the estop) went out
    pid: int | None = None
    continued_at: float | None = None  # stop_at: when SIGCONT was sent
    skipped: str | None = None
    sent: int = 0                      # estop_at: commands sent (the button stays held)
    periods: int = 0                   # estop_at: ESTOP_PERIODs since SEC that the commands sent have covered

    def next_estop(self) -> float:
        """estop_at: when the held button's next command is due (s on the run's clock)."""
        return self.fault.at + self.periods * ESTOP_PERIOD

    def report(self) -> dict:
        late = None if self.done_at is None else round(self.done_at - self.fault.at, 6)
        return {"fault": self.fault.describe(), "target": self.fault.target, "action": self.fault.action,
                "planned_at": self.fault.at, "done_at": self.done_at, "late_by": late, "pid": self.pid,
                "continued_at": self.continued_at, "skipped": self.skipped,
                **({"sent": self.sent} if self.fault.action == "estop" else {})}


def _wait_ready(child, ready: Path, failure: str) -> None:
    """Until `child` has written its `ready` file; RuntimeError(`failure`) if it exits or READY_TIMEOUT passes."""
    deadline = time.monotonic() + READY_TIMEOUT
    while not ready.exists():
        if child.popen.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(failure)
        time.sleep(0.05)


@dataclass
class FaultStack:
    plan: FaultPlan
    relay_endpoint: str | None = None
    can_ports: tuple[int, int] | None = None
    infra: dict = field(default_factory=dict)            # name -> Child (relay, gateway)
    stats_files: dict = field(default_factory=dict)
    injections: list[Injection] = field(default_factory=list)
    killed: dict = field(default_factory=dict)           # name -> the Child that was killed on purpose
    stopped: dict = field(default_factory=dict)          # name -> (Child, injection)
    killed_reports: list = field(default_factory=list)
    armed_at: float | None = None                        # s on the run's clock when the demo armed the faults
    gateway_priority: str | None = None
    t0: float | None = None                              # the run's t = 0, monotonic
    origin_file: Path | None = None                      # where t = 0 goes for the relay and the gateway
    estop_sender: object = None                          # callable that sends an estop command, or None
    clock: object = time.monotonic                       # the monotonic clock the faults are timed on
    bus: object = None                                   # the drives' bus (can_bus.BusSpec) for an intruder
    router: object = None                                # the --secure stack, for router.restart_at
    publish: object = None                               # callable(payload bytes) on the operator command key
    captured: tuple | None = None                        # (payload, attachment): another session's last command
    listener: object = None                              # a session the console connects to (evict, plain Zenoh)
    capture: object = None                               # the subscriber that captures the holder's commands
    threads: list = field(default_factory=list)
    intrusions: dict = field(default_factory=dict)       # action -> what it did (counts), for the report

    @property
    def has_estops(self) -> bool:
        return any(f.action == "estop" for f in self.plan.processes)

    @classmethod
    def from_args(cls, args) -> "FaultStack":
        """Parse ``--fault``/``--fault-seed``; raises FaultSpecError (a ValueError) on a bad spec."""
        plan = parse(list(args.fault or []), args.fault_seed)
        return cls(plan, injections=[Injection(f) for f in plan.processes])

    @property
    def empty(self) -> bool:
        return self.plan.empty

    @property
    def needs_relay(self) -> bool:
        return self.plan.has("operator") or self.plan.has("telemetry")

    # ----- wiring ------------------------------------------------------------
    def console_endpoint(self, controller_ep: str, free_port) -> str:
        if not self.needs_relay:
            return controller_ep
        self.relay_endpoint = f"tcp/127.0.0.1:{free_port()}"
        return self.relay_endpoint

    def can_arguments(self, can: list[str], free_udp_port) -> tuple[list[str], list[str]]:
        """(controller's CAN arguments, robot's): the same bus unless CAN faults need a gateway."""
        if not self.plan.has("can"):
            return can, can
        self.can_ports = (free_udp_port(), free_udp_port())
        return ([*can[:2], "--can-option", f"port={self.can_ports[0]}"],
                [*can[:2], "--can-option", f"port={self.can_ports[1]}"])

    def fault_argv(self) -> list[str]:
        argv = [a for spec in self.plan.specs for a in ("--fault", spec)]
        argv += ["--fault-seed", str(self.plan.seed), "--arm-on-signal"]
        return argv + (["--origin-file", str(self.origin_file)] if self.origin_file is not None else [])

    def start(self, controller_ep: str, robot_id: str, log_dir: Path,
              backstop: str, start_child, relay_zenoh: list[str] | None = None) -> None:
        """Start the relay and/or the gateway (before the robot, console and controller); `relay_zenoh`: the relay's
        Zenoh arguments behind the --secure routers (its two client configurations) instead of listen/connect."""
        self.origin_file = log_dir / "fault-origin.json"
        self.origin_file.unlink(missing_ok=True)
        if self.can_ports is not None:
            stats, ready = log_dir / "fault-gateway.json", log_dir / "fault-gateway.ready"
            self.stats_files["gateway"] = stats
            self.infra["gateway"] = start_child("fault-gateway", [
                "fault-gateway", "--controller-port", str(self.can_ports[0]), "--robot-port", str(self.can_ports[1]),
                *self.fault_argv(), "--stats", str(stats), "--ready", str(ready), "--duration", backstop,
                "--realtime"], log_dir)
            # in the torque loop's path: the controller's priority (nice −10, SCHED_FIFO) when allowed; at
            # normal priority on an overloaded host frames were measured waiting ~200 ms in its buffer
            self.gateway_priority = raise_priority(self.infra["gateway"].popen.pid)
            _wait_ready(self.infra["gateway"], ready, "the CAN fault gateway did not come up")
        if self.relay_endpoint is not None:
            stats = log_dir / "fault-relay.json"
            self.stats_files["relay"] = stats
            ready = log_dir / "fault-relay.ready"
            ready.unlink(missing_ok=True)
            zenoh_args = relay_zenoh or ["--listen", self.relay_endpoint, "--connect", controller_ep]
            self.infra["relay"] = start_child("fault-relay", [
                "fault-relay", *zenoh_args, "--robot-id", robot_id, *self.fault_argv(), "--stats", str(stats),
                "--ready", str(ready), "--duration", backstop], log_dir)
            _wait_ready(self.infra["relay"], ready, "the Zenoh fault relay did not come up"
                        + ("" if relay_zenoh else f" on {self.relay_endpoint}"))

    # ----- during the run ------------------------------------------------------
    def robot_arguments(self) -> list[str]:
        """The robot's extra arguments: what its SIGUSR2 restarts (robot.reboot_at)."""
        for fault in self.plan.processes:
            if fault.action == "reboot":
                return ["--drive-restart", f"{fault.params[0]:g},{fault.params[1]:g}"]
        return []

    def console_listener(self, free_port, open_session) -> list[str]:
        """`operator.evict_at` without a router: Zenoh peers do not forward, so the demo hears the console's
        commands only on a session the console connects to. Opens it; returns the console's extra arguments."""
        if not any(f.action == "evict" for f in self.plan.processes):
            return []
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.listener = open_session(listen=[endpoint])
        return ["--zenoh-connect", endpoint]

    @property
    def needs_operator_session(self) -> bool:
        return any(f.action in ("estop", "flood", "evict") for f in self.plan.processes)

    @property
    def sends_estop(self) -> bool:
        return any(f.action == "estop" for f in self.plan.processes)

    def attach(self, session, listener, robot_id: str, signer=None) -> None:
        """The demo's own sessions: `operator.estop_at`, `flood_at` and `evict_at` publish on `session` (one that
        may publish operator commands), straight to the controller; `evict_at` listens on `listener` (one that
        receives them) for the lease holder's commands, and replays one with its attachment (a signature, if the
        holder signs). `signer` (security/signing.py): the estop is signed by that operator (`ESTOP_OPERATOR`,
        trusted by a controller with an operators file); floods and junk sessions are never signed."""
        if not self.needs_operator_session:
            return
        from sharedctl.protocol import keys
        from sharedctl.protocol.messages import ControlRequest, OperatorCommand
        from sharedctl.protocol.msgpack_codec import encode_message

        from .. import zenoh_qos
        from ..lifecycle import steady_wall
        key = keys.operator_cmd_key(robot_id)
        publisher = zenoh_qos.declare_publisher(session, key)
        self.publish = publisher.put
        if any(f.action == "evict" for f in self.plan.processes):
            from sharedctl.protocol.msgpack_codec import decode_message

            def capture(sample) -> None:          # the lease holder's (the console's), not the faults' own
                payload = sample.payload.to_bytes()
                try:
                    if not decode_message(payload, expect=OperatorCommand).operator_id.startswith("fault-"):
                        self.captured = (payload, None if sample.attachment is None else sample.attachment.to_bytes())
                except Exception:  # noqa: BLE001 — whatever else is on the key is not worth capturing
                    pass
            self.capture = listener.declare_subscriber(keys.operator_cmd_key(robot_id), capture)
        session_id = f"estop-{os.getpid()}"
        seq = iter(range(1, 1 << 30))
        zeros = (0.0, 0.0, 0.0)

        def send() -> None:
            payload = encode_message(OperatorCommand(
                operator_id=ESTOP_OPERATOR, session_id=session_id, seq=next(seq), send_time=steady_wall(),
                joystick=zeros, q_d=zeros, qd_d=zeros, qdd_d=zeros, deadman=False, estop=True,
                control_request=ControlRequest.NONE))
            publisher.put(payload, attachment=None if signer is None else signer.attachment(key, payload))
        self.estop_sender = send

    def arm(self, t0: float, lease_wall: float | None = None) -> None:
        """The run's t = 0 is `t0` (monotonic; `lease_wall`: the same instant on the wall clock, for the
        relay and the gateway): faults act from now on, timed ones on that clock."""
        if self.t0 is not None:
            return
        self.t0 = t0
        if self.origin_file is not None and self.infra:
            wall = lease_wall if lease_wall is not None else time.time() - (self.clock() - t0)
            tmp = self.origin_file.with_suffix(".tmp")
            tmp.write_text(json.dumps({"lease_wall": wall}))
            tmp.replace(self.origin_file)
        for child in self.infra.values():
            if child.popen.poll() is None:
                child.popen.send_signal(signal.SIGUSR1)
        self.armed_at = self.clock() - t0

    def expected_dead(self, name: str) -> bool:
        return name in self.killed

    def next_due(self) -> float | None:
        """The monotonic instant the next process fault (or SIGCONT) is due; None if none is pending."""
        if self.t0 is None:
            return None
        times = [inj.fault.at for inj in self.injections if inj.done_at is None and inj.skipped is None]
        times += [inj.fault.at + inj.fault.duration for inj in self.injections
                  if inj.fault.action == "stop" and inj.done_at is not None and inj.continued_at is None]
        times += [inj.next_estop() for inj in self.injections if inj.fault.action == "estop" and inj.sent]
        return self.t0 + min(times) if times else None

    def wait_time(self, now: float) -> float:
        """How long the supervision loop may sleep at `now`: POLL, or less if a fault is due sooner."""
        due = self.next_due()
        return POLL if due is None else min(POLL, max(due - now, 0.0))

    def tick(self, now: float, children: dict, restart) -> str | None:
        """Carry out the process faults that are due; returns a failure reason if the relay/gateway died."""
        if self.t0 is None:
            return None
        t = now - self.t0
        for inj in self.injections:
            if inj.done_at is None and inj.skipped is None and t >= inj.fault.at:
                self._inject(inj, children, restart)
            if inj.fault.action == "stop" and inj.done_at is not None and inj.continued_at is None \
                    and t >= inj.fault.at + inj.fault.duration:
                self._continue(inj, self._clock())
            if inj.fault.action == "estop" and inj.sent and t >= inj.next_estop():
                self._send_estop(inj, t)
        dead = [name for name, child in self.infra.items() if child.popen.poll() is not None]
        return f"the fault {', '.join(dead)} exited during the run" if dead else None

    def _clock(self) -> float:
        """Now on the run's clock (s since t = 0)."""
        return self.clock() - self.t0

    def _inject(self, inj: Injection, children: dict, restart) -> None:
        name, action = inj.fault.target, inj.fault.action
        if action in ("intrude", "flood", "evict", "bounce", "reboot"):
            self._intrude(inj, children)
            return
        if action == "estop":
            if self.estop_sender is None:
                inj.skipped = "no session to send the estop on"
                return
            inj.done_at = self._clock()
            self._send_estop(inj, t=inj.done_at)
            return
        if action == "restart":
            if name not in self.killed:
                inj.skipped = "not killed"
                return
            inj.done_at = self._clock()
            children[name] = restart()
            inj.pid = children[name].popen.pid
            del self.killed[name]
            return
        child = children.get(name)
        if child is None or child.popen.poll() is not None:
            inj.skipped = "not running"
            return
        inj.pid = child.popen.pid
        if action == "kill":
            inj.done_at = self._clock()
            child.popen.kill()       # SIGKILL to our own child, by PID
            child.popen.wait()
            self.killed[name] = child
            self._record_killed(name, child)
        else:
            inj.done_at = self._clock()
            os.kill(child.popen.pid, signal.SIGSTOP)
            self.stopped[name] = (child, inj)

    def _send_estop(self, inj: Injection, t: float) -> None:
        """One command of the held estop; a late wake-up sends one, not the ones it missed."""
        self.estop_sender()
        inj.sent += 1
        inj.periods = max(inj.periods + 1, int((t - inj.fault.at) / ESTOP_PERIOD) + 1)

    def _intrude(self, inj: Injection, children: dict) -> None:
        """An intrusion (spec.INTRUSIONS): a signal now, or a thread of its own for what takes time."""
        fault = inj.fault
        if fault.action == "reboot":
            robot = children.get("robot")
            if robot is None or robot.popen.poll() is not None:
                inj.skipped = "not running"
                return
            inj.done_at, inj.pid = self._clock(), robot.popen.pid
            robot.popen.send_signal(signal.SIGUSR2)
            return
        work = {"intrude": self._foreign_master, "flood": self._flood, "evict": self._evict,
                "bounce": self._bounce_router}[fault.action]
        needs = {"intrude": self.bus, "flood": self.publish, "evict": self.publish, "bounce": self.router}
        if needs[fault.action] is None:
            inj.skipped = {"intrude": "no CAN bus to join", "bounce": "no router (needs --secure)"}.get(
                fault.action, "no session to publish on")
            return
        inj.done_at = self._clock()
        thread = threading.Thread(target=work, args=(fault,), name=f"fault-{fault.action}", daemon=True)
        thread.start()
        self.threads.append(thread)

    def _foreign_master(self, fault: ProcessFault) -> None:
        from sharedctl.protocol import cansimple as cs

        from ..can_bus import open_transport
        transport = open_transport(self.bus)
        sent = 0
        try:
            arbitration_id, data = cs.torque_frame(INTRUDER_NODE, INTRUDER_TORQUE)
            end = time.monotonic() + fault.duration
            while time.monotonic() < end:
                transport.send(arbitration_id, False, len(data), data)
                sent += 1
                time.sleep(1.0 / fault.hz)
        finally:
            transport.shutdown()
        self.intrusions["intrude"] = {"frames": sent, "node": INTRUDER_NODE, "torque_nm": INTRUDER_TORQUE}

    def _operator_commands(self, session_id: str, first_seq: int = 1, **fields):
        from sharedctl.protocol.messages import ControlRequest, OperatorCommand
        from sharedctl.protocol.msgpack_codec import encode_message

        from ..lifecycle import steady_wall
        seq = first_seq
        while True:
            yield encode_message(OperatorCommand(
                operator_id=f"fault-{session_id}", session_id=session_id, seq=seq, send_time=steady_wall(),
                joystick=fields.get("joystick", (0.0, 0.0, 0.0)), q_d=fields["q_d"], qd_d=(0.0, 0.0, 0.0),
                qdd_d=(0.0, 0.0, 0.0), deadman=fields.get("deadman", False), estop=False,
                control_request=ControlRequest.NONE))
            seq += 1

    def _flood(self, fault: ProcessFault) -> None:
        """A session that never held the lease, full deflection, at HZ for DURATION."""
        commands = self._operator_commands(f"flood{os.getpid()}", joystick=(1.0, 1.0, 1.0), deadman=True,
                                           q_d=(0.0, 0.0, 0.0))
        sent, end = 0, time.monotonic() + fault.duration
        while time.monotonic() < end:
            self.publish(next(commands))
            sent += 1
            time.sleep(1.0 / fault.hz)
        self.intrusions["flood"] = {"commands": sent, "rate_hz": fault.hz}

    def _evict(self, fault: ProcessFault) -> None:
        """200 sessions of one command each, then the holder's last command as it was captured (its signature too)."""
        captured = self.captured
        for k in range(EVICTING_SESSIONS):
            self.publish(next(self._operator_commands(f"evict{os.getpid()}x{k}", q_d=(0.0, 0.0, 0.0))))
        if captured is not None:
            self.publish(captured[0], attachment=captured[1])
        self.intrusions["evict"] = {"sessions": EVICTING_SESSIONS, "replayed": captured is not None}

    def _bounce_router(self, fault: ProcessFault) -> None:
        self.intrusions["bounce"] = self.router.bounce(fault.duration)

    def _record_killed(self, name: str, child) -> None:
        child.exit_code = child.popen.returncode
        child.stop_seconds = 0.0
        self.killed_reports.append({"name": name, **child.report(), "signal": "SIGKILL (injected)"})

    def _continue(self, inj: Injection, t: float | None) -> None:
        child, _ = self.stopped.pop(inj.fault.target, (None, None))
        if child is not None and child.popen.poll() is None:
            os.kill(child.popen.pid, signal.SIGCONT)
        inj.continued_at = t

    def continue_all(self) -> None:
        """SIGCONT every child still stopped (before the demo stops them)."""
        now = None if self.t0 is None else self._clock()
        for inj in [i for i in self.injections if i.fault.action == "stop" and i.done_at is not None
                    and i.continued_at is None]:
            self._continue(inj, now)

    # ----- after the run ---------------------------------------------------------
    def stop(self) -> None:
        self.continue_all()
        for thread in self.threads:
            thread.join(timeout=10.0)
        if self.capture is not None:
            self.capture.undeclare()
        for child in self.infra.values():
            child.stop(5.0)
        if self.listener is not None:
            self.listener.close()

    def report(self) -> dict:
        out: dict = {"seed": self.plan.seed, "armed_at": self.armed_at, "scheduling_tolerance": SCHEDULING_TOLERANCE,
                     "processes": [inj.report() for inj in self.injections],
                     "killed": self.killed_reports, "intrusions": dict(self.intrusions)}
        for name, path in self.stats_files.items():
            try:
                stats = json.loads(Path(path).read_text())
            except (OSError, ValueError):
                stats = {"error": f"no counters from the fault {name}"}
            out[name] = _with_rates(stats)
            child = self.infra.get(name)
            if child is not None:
                out[name]["exit_code"] = child.exit_code
        if "gateway" in out:
            out["gateway"]["priority"] = self.gateway_priority
        return out

    def judge(self, summary: dict, children: dict, result: dict, failure: str | None) -> bool:
        """``ok`` under intended faults (see the module docstring); the reasons against go to
        ``summary["injected"]["not_ok"]``."""
        reasons = [failure] if failure else []
        reasons += [f"{c.name} exited {c.exit_code}" + (" (SIGKILL after the stop timeout)" if c.killed else "")
                    for name, c in children.items() if name not in self.killed and not c.clean]
        reasons += [f"fault {name} exited {c.exit_code}" for name, c in self.infra.items() if not c.clean]
        if result["violations"]:
            reasons.append(f"{result['violations']} ground-truth violations")
        if not result["truth_samples"]:
            reasons.append("no ground truth recorded")
        early = [e for e in result.get("event_log", []) if e["kind"] == "estop" and e["t"] < 0]
        if early:   # before the faults were armed: not a fault's doing, the run never started
            reasons.append(f"emergency stop before the run started (t={early[0]['t']} s): {early[0]['text']}")
        summary.setdefault("injected", {})["not_ok"] = reasons
        return not reasons


def _with_rates(stats: dict) -> dict:
    """Add the measured rates next to the raw counters of each stream."""
    for value in stats.values():
        if isinstance(value, dict) and value.get("received"):
            n = value["received"]
            dropped = sum(value.get(k, 0) for k in ("lost", "burst_lost", "blackout_dropped", "rate_dropped"))
            value["measured_drop_rate"] = dropped / n
            value["measured_duplicate_rate"] = value.get("duplicated", 0) / n
            value["measured_corrupt_rate"] = value.get("corrupted", 0) / n
    return stats
