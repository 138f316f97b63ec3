"""Operator authority against the real processes: `sharedctl robot` + `sharedctl controller --lease explicit`,
operators as loopback Zenoh sessions of this test (lease queries with the console's `LeaseClient`).

Effect is read from the controller's own telemetry: `u_h` in RobotState is k_p ∘ (the deflection of
the command the controller is using), `lease_holder` the holder, `link.rejected_messages` the
count of refused operator messages, `estop_active` the estop.
"""
from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from sharedctl.protocol import keys
from sharedctl.protocol.messages import ControlRequest, Event, LeaseAction, OperatorCommand, RobotState
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.services import zenoh_session
from sharedctl.services.children import free_udp_port
from sharedctl.services.console.lease_client import LeaseClient
from sharedctl.services.scenario_files import load

from .processes import reap, wait_for

pytestmark = pytest.mark.processes

ROBOT = "leasebot"
KP = load("paper_convex").closed_loop()[0].human.kp


class Operator:
    """One operator session: lease queries and commands with its own seq and wall-clock send times."""

    def __init__(self, session, operator_id: str, session_id: str, publisher) -> None:
        self.session, self.pub = session, publisher
        self.lease = LeaseClient(ROBOT, operator_id, session_id, want=False)
        self.operator_id, self.session_id = operator_id, session_id
        self.seq = 0
        self.last = b""

    def take(self):
        return self.lease.ask(self.session, LeaseAction.TAKE)

    def release(self):
        return self.lease.ask(self.session, LeaseAction.RELEASE)

    def command(self, joystick, *, estop=False, request=ControlRequest.NONE, seq=None) -> bytes:
        if seq is None:
            self.seq += 1
        payload = encode_message(OperatorCommand(
            operator_id=self.operator_id, session_id=self.session_id, seq=self.seq if seq is None else seq,
            send_time=time.time(), joystick=joystick, q_d=(-0.9, 2.0, 0.0), qd_d=(0.0, 0.0, 0.0),
            qdd_d=(0.0, 0.0, 0.0), deadman=True, estop=estop, control_request=request))
        self.pub.put(payload)
        self.last = payload
        return payload


class System:
    def __init__(self, session) -> None:
        self.session = session
        self.states: list[RobotState] = []
        self.lock = threading.Lock()
        self.events: list[Event] = []
        self.operators: dict = {}
        self.sub = session.declare_subscriber(keys.state_key(ROBOT), self._on_state)
        self.event_sub = session.declare_subscriber(
            keys.events_key(ROBOT), lambda s: self.events.append(decode_message(s.payload.to_bytes(), expect=Event)))
        self.pub = session.declare_publisher(keys.operator_cmd_key(ROBOT))

    def _on_state(self, sample) -> None:
        state = decode_message(sample.payload.to_bytes(), expect=RobotState)
        with self.lock:
            self.states.append(state)

    def latest(self) -> RobotState:
        with self.lock:
            return self.states[-1]

    def since(self, n: int) -> list[RobotState]:
        with self.lock:
            return self.states[n:]

    def operator(self, operator_id: str, session_id: str) -> Operator:
        """The same operator session across tests (its seqs go on increasing)."""
        key = (operator_id, session_id)
        if key not in self.operators:
            self.operators[key] = Operator(self.session, operator_id, session_id, self.pub)
        return self.operators[key]


def drive(op: Operator, joystick, seconds: float, between=None) -> None:
    """Commands at 50 Hz for `seconds`; `between()` after each (e.g. another operator's message)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        op.command(joystick)
        if between is not None:
            between()
        time.sleep(0.02)


@pytest.fixture(scope="module")
def system():
    port, z_robot, z_ctrl = free_udp_port(), zenoh_session.free_loopback_port(), zenoh_session.free_loopback_port()
    can = ["--can-interface", "udp_multicast", "--can-option", f"port={port}", "--robot-id", ROBOT]
    cli = [sys.executable, "-m", "sharedctl.services.cli"]
    procs = [
        subprocess.Popen(["nice", "-n", "-10", *cli, "robot", *can, "--zenoh-listen", f"tcp/127.0.0.1:{z_robot}"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL),
        subprocess.Popen(cli + ["controller", *can, "--zenoh-listen", f"tcp/127.0.0.1:{z_ctrl}", "--quiet",
                                "--feedback-timeout-ms", "150", "--lease", "explicit"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True),
    ]
    session = None
    try:
        wait_for(lambda: listening(z_ctrl), 30.0, "the controller's Zenoh endpoint")   # no connect back-off
        session = zenoh_session.open_session(connect=[f"tcp/127.0.0.1:{z_ctrl}"])
        sys_ = System(session)
        wait_for(lambda: sys_.states, 30.0, "the controller's telemetry")
        probe = sys_.operator("probe", "p1")                   # armed and driving: a command shows in u_h
        assert probe.take().granted
        wait_for(lambda: probe.command((0.0, -0.05, 0.0)) and u_h_is(sys_.latest(), (0.0, -0.05, 0.0)), 30.0,
                 "the controller armed and applying commands")
        assert probe.release().granted
        yield sys_, procs[1]
    finally:
        if session is not None:
            session.close()
        reap(procs)


def listening(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        time.sleep(0.05)
        return False


def u_h_is(state: RobotState, joystick) -> bool:
    return np.allclose(state.u_h, KP * np.asarray(joystick), atol=1e-9)


def running(sys_: System, holder: Operator) -> None:
    """Re-arm (the holder's in-band take) should a starved simulator have tripped an estop earlier."""
    if sys_.latest().estop_active:
        holder.command((0.0, 0.0, 0.0), request=ControlRequest.TAKE)
    wait_for(lambda: holder.command((0.0, 0.0, 0.0)) and not sys_.latest().estop_active, 10.0,
             "the controller re-armed")


def test_1_a_second_operator_cannot_take_control_while_a_lease_is_held(system):
    sys_, _ = system
    alice, bob = sys_.operator("alice", "a1"), sys_.operator("bob", "b1")
    assert alice.take().granted
    reply = bob.take()
    assert not reply.granted and reply.holder == "alice"
    wait_for(lambda: sys_.latest().lease_holder == "alice", 2.0, "RobotState naming alice as the holder")


def test_2_commands_from_a_non_holder_have_no_effect(system):
    sys_, _ = system
    alice, bob = sys_.operator("alice", "a1"), sys_.operator("bob", "b1")
    alice.take()
    running(sys_, alice)
    mine, theirs = (0.0, -0.05, 0.0), (-1.0, -1.0, 0.0)     # the start pose is 0.1 m from the face x = -1
    drive(alice, mine, 0.3)
    wait_for(lambda: u_h_is(sys_.latest(), mine), 2.0, "alice's deflection in u_h")
    before, n = sys_.latest().link.rejected_messages, len(sys_.states)
    sent = []
    drive(alice, mine, 0.6, between=lambda: sent.append(bob.command(theirs)))
    wait_for(lambda: sys_.latest().link.rejected_messages >= before + len(sent), 2.0, "bob's commands counted")
    window = sys_.since(n)
    assert len(window) > 10 and all(s.lease_holder == "alice" for s in window)
    assert not any(u_h_is(s, theirs) for s in window)
    assert sum(u_h_is(s, mine) and not s.estop_active for s in window) > 0.5 * len(window)   # alice drives
    assert sys_.latest().link.rejected_messages == before + len(sent)


def test_3_replayed_and_out_of_order_commands_have_no_effect(system):
    sys_, _ = system
    alice = sys_.operator("alice", "a1")
    alice.take()
    running(sys_, alice)
    mine, old = (0.0, -0.05, 0.0), (0.05, 0.0, 0.0)
    captured = alice.command(old)                   # a real command, captured on the wire …
    late = alice.command(old)
    drive(alice, mine, 0.3)
    wait_for(lambda: u_h_is(sys_.latest(), mine), 2.0, "the current deflection in u_h")
    before, n = sys_.latest().link.rejected_messages, len(sys_.states)
    replays = []

    def replay():
        sys_.pub.put(alice.last)                                          # the newest, delivered twice
        sys_.pub.put(captured)                                            # … re-sent later (an older seq)
        sys_.pub.put(late)
        replays.extend((alice.last, captured, late))

    drive(alice, mine, 0.6, between=replay)
    wait_for(lambda: sys_.latest().link.rejected_messages >= before + len(replays), 2.0, "the replays counted")
    window = sys_.since(n)
    assert len(window) > 10 and not any(u_h_is(s, old) for s in window)
    assert sum(u_h_is(s, mine) and not s.estop_active for s in window) > 0.5 * len(window)
    assert sys_.latest().link.rejected_messages == before + len(replays)


def test_4_after_release_a_second_operator_can_take_control(system):
    sys_, _ = system
    alice, bob = sys_.operator("alice", "a1"), sys_.operator("bob", "b1")
    alice.take()
    assert alice.release().granted
    assert bob.take().granted
    wait_for(lambda: sys_.latest().lease_holder == "bob", 2.0, "RobotState naming bob")
    assert not alice.take().granted


def test_5_after_expiry_a_second_operator_can_take_control(system):
    sys_, _ = system
    bob, carol = sys_.operator("bob", "b1"), sys_.operator("carol", "c1")
    assert bob.take().granted                     # renewed; from now on bob is silent
    t0 = time.monotonic()
    assert not carol.take().granted
    wait_for(lambda: sys_.latest().lease_holder is None, 3.0, "the lease to expire")
    assert time.monotonic() - t0 > 0.9            # not before the stated 1 s (less the telemetry period)
    assert carol.take().granted


def test_6_estop_from_a_non_holder_works(system):
    sys_, _ = system
    carol, dave = sys_.operator("carol", "c1"), sys_.operator("dave", "d1")
    assert carol.take().granted
    running(sys_, carol)
    assert not sys_.latest().estop_active, [e.text for e in sys_.events]
    dave.command((0.0, 0.0, 0.0), estop=True)
    wait_for(lambda: sys_.latest().estop_active, 2.0, "the estop from the non-holder")
    assert sys_.latest().lease_holder == "carol"   # the estop does not hand over control
