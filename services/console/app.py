"""The console process: telemetry in, operator commands out, a live dashboard on a terminal.

Threads: Zenoh's callbacks store the latest RobotState and the events (`Telemetry`); a sender
thread publishes one OperatorCommand every 1/rate s (`RateClock`); the main thread reads the
keyboard and redraws the dashboard (5 Hz), so a slow redraw never delays a command.

Script mode: the scenario's scripted operator drives; its clock starts when the first
RobotState arrives (the controller is up), and nothing is sent before that. Keyboard mode:
the virtual joystick drives (before the first RobotState its wish is around the scenario's
initial pose). Gamepad mode: a gamepad drives instead (gamepad.py), read by its own thread
(gamepad_device.py); when its enable button is let go, it is unplugged or it presses estop, the
sender sends at once instead of at its next tick. In every mode X/Esc requests an emergency stop
and C clears the request (in gamepad mode also the pad's).

Hands-off when the console cannot see (keyboard and gamepad mode): while its own UI loop has not run for
`UI_STALE` s (frozen terminal, stalled redraw) or the last RobotState is older than
`TELEMETRY_STALE` s (the operator would drive on an old picture), or the gamepad is unplugged or
resynchronising after dropped events, every command goes out with the
deadman released, no deflection and the wish at the last known pose (an estop request still goes
out); the dashboard says why. The scripted operator follows its script whatever it sees.
Send times come from a wall clock that never steps (`lifecycle.steady_wall`), so a step of this
host's clock cannot make its commands look stale to the controller.

Control (lease_client.py): the console takes the operator authority lease at start (retrying
until the controller answers), T takes and R releases it, a clean end hands it back, and
commands are sent only while this console holds control — an estop request always. The
script's clock starts when the first RobotState has arrived and control is held.
"""
from __future__ import annotations

import sys
import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from sharedctl.protocol import keys
from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.messages import Event, OperatorCommand, RobotState
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.protocol.wire_types import ROBOT_DIMS

from .. import zenoh_qos
from ..lifecycle import RateClock, StopFlag
from ..security.zenoh_config import open_configured
from .dashboard import DashboardView, map_size, render
from .keyboard import VirtualJoystick, parse_keys
from .lease_client import LeaseClient
from .map_view import MapFrame, background
from .operator import CommandCounter, JoystickCommandSource, ScriptedCommandSource
from .terminal import KeyReader

REDRAW_PERIOD = 0.2   # s
KEYS_SCRIPT = "script drives · x/Esc estop · c clear estop · t/r take/release · Ctrl-C quit"
KEYS_KEYBOARD = "arrows/WASD move · q/e yaw · space deadman · x/Esc estop · c clear · t/r take/release · Ctrl-C quit"
KEYS_GAMEPAD = "the gamepad drives · x/Esc estop · c clear estop · t/r take/release · Ctrl-C quit"
GAMEPAD_KEYS = ("x", "esc", "c", "t", "r")    # the terminal's keys that still count while a gamepad drives


@dataclass
class ConsoleOptions:
    scenario: object                 # sharedctl.scenario.Scenario (map, initial pose, script)
    script: bool = False
    headless: bool = True
    duration: float | None = None    # s, stop by itself after this long
    listen: list[str] | None = None
    connect: list[str] | None = None
    robot_id: str = "robot1"
    operator_id: str = "operator"
    rate: float = 50.0               # Hz
    deadman_mode: str = "hold"
    zenoh_config: str | None = None  # Zenoh JSON5 file (credentials, TLS, mode); endpoints above replace its own
    signer: object = None            # security.signing.Signer: commands and lease queries signed; None: unsigned
    gamepad: object = None           # gamepad_device.GamepadReader, opened: the pad drives (instead of the keys)


class Telemetry:
    """Latest RobotState and recent events, filled by Zenoh callbacks (any thread)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.state: RobotState | None = None
        self.state_arrival: float | None = None     # monotonic s
        self.first_arrival: float | None = None
        self.time_origin = 0.0                      # the first RobotState's time (controller clock)
        self.states = 0
        self.events: deque = deque(maxlen=6)
        self.event_count = 0
        self.rejected = 0
        self.trail: deque = deque(maxlen=400)
        self.lease_listener = None                  # called with (lease_holder, time) of every RobotState

    def on_state(self, sample) -> None:
        try:
            state = decode_message(sample.payload.to_bytes(), ROBOT_DIMS, expect=RobotState)
        except ProtocolError:
            with self.lock:
                self.rejected += 1
            return
        now = time.monotonic()
        with self.lock:
            if self.first_arrival is None:
                self.first_arrival, self.time_origin = now, state.time
            self.state, self.state_arrival = state, now
            self.states += 1
            if not self.trail or np.hypot(state.q[0] - self.trail[-1][0], state.q[1] - self.trail[-1][1]) > 0.02:
                self.trail.append((state.q[0], state.q[1]))
        if self.lease_listener is not None:
            self.lease_listener(state.lease_holder, state.time)

    def on_event(self, sample) -> None:
        try:
            event = decode_message(sample.payload.to_bytes(), ROBOT_DIMS, expect=Event)
        except ProtocolError:
            with self.lock:
                self.rejected += 1
            return
        with self.lock:
            self.events.append(event)
            self.event_count += 1


UI_STALE = 0.5          # s without a run of the UI loop: the console's operator sees nothing new
TELEMETRY_STALE = 0.5   # s since the last RobotState: the picture the operator drives on is that old


class ConsoleApp:
    def __init__(self, options: ConsoleOptions) -> None:
        self.options = options
        loop, q0, _ = options.scenario.closed_loop()
        self.loop, self.q0 = loop, np.asarray(q0, float)
        counter = CommandCounter(operator_id=options.operator_id)
        self.script = ScriptedCommandSource(loop.human, counter) if options.script else None
        self.keyboard = JoystickCommandSource(VirtualJoystick(deadman_mode=options.deadman_mode), counter)
        self.gamepad = options.gamepad if not options.script else None
        self.gamepad_source = None if self.gamepad is None else JoystickCommandSource(self.gamepad.pad, counter)
        self.urgent = threading.Event()       # set: the sender sends now (the pad stopped driving, or estop)
        self.telemetry = Telemetry()
        self.lease = LeaseClient(options.robot_id, options.operator_id, counter.session_id, signer=options.signer)
        self.telemetry.lease_listener = self.lease.on_state
        self.script_origin: float | None = None    # monotonic s: the script's t = 0
        self.lock = threading.Lock()          # guards the joystick and `last_command`
        self.last_command: OperatorCommand | None = None
        self.sent = 0
        self.publish_errors = 0
        self.ui_alive_at = time.monotonic()   # the UI loop's last run (monotonic s)
        self.blind: str | None = None          # why commands go out hands-off, None while the operator sees
        self.blind_commands = 0

    # ----- commands ---------------------------------------------------------
    def next_command(self, now: float) -> OperatorCommand | None:
        """The command to send at monotonic time `now` (None: nothing to send yet)."""
        with self.telemetry.lock:
            state, arrival = self.telemetry.state, self.telemetry.state_arrival
        holding = self.lease.holding
        with self.lock:
            estop = self.keyboard.joystick.estop
            if self.script is not None:
                if state is None or not (holding or estop):
                    return None
                if self.script_origin is None:
                    self.script_origin = now
                return self.script.command(now - self.script_origin, state, estop=estop)
            pose = self.q0 if state is None else np.asarray(state.q, float)
            self.blind = blind(now, self.ui_alive_at, arrival)
            source = self.keyboard
            if self.gamepad_source is not None:
                source, pad = self.gamepad_source, self.gamepad_source.joystick
                self.blind = self.blind or pad.status
                estop = estop or pad.estop
            command = source.command(now, pose, hands_off=self.blind is not None, estop=estop)
            if self.blind is not None and (holding or command.estop):
                self.blind_commands += 1
            return command if holding or command.estop else None

    def sender(self, publisher, stop: StopFlag) -> None:
        """One command every 1/rate s; one more at once whenever `urgent` is set (off the grid, which stays)."""
        clock = RateClock(1.0 / self.options.rate)
        while not stop.stopped:
            self.send(publisher, time.monotonic())
            while self.urgent.wait(max(0.0, clock.next - time.monotonic())):
                self.urgent.clear()
                if stop.stopped:
                    return
                self.send(publisher, time.monotonic())
            clock.wait()

    def send(self, publisher, now: float) -> None:
        command = self.next_command(now)
        if command is None:
            return
        signer, key = self.options.signer, str(publisher.key_expr)
        try:
            payload = encode_message(command, ROBOT_DIMS)
            publisher.put(payload, attachment=None if signer is None else signer.attachment(key, payload))
            self.sent += 1
        except Exception:  # noqa: BLE001 — a failed put must not end the operator loop
            self.publish_errors += 1
        with self.lock:
            self.last_command = command

    def on_keys(self, pressed: list[str], now: float) -> None:
        """Keys typed on the terminal (keyboard.py's names); while a gamepad drives, only estop, clear and
        take/release count, and C clears the pad's estop request too."""
        if self.gamepad_source is not None:
            pressed = [key for key in pressed if key in GAMEPAD_KEYS]
        with self.lock:
            self.keyboard.joystick.press_all(pressed, now)
            if self.gamepad_source is not None and "c" in pressed:
                self.gamepad_source.joystick.clear_estop()
        for key in pressed:
            if key in ("t", "r"):
                self.lease.want(key == "t")

    def on_gamepad(self, actions: list[str]) -> None:
        """The pad's actions (gamepad.py), from its reader thread."""
        for action in actions:
            if action in ("take", "release"):
                self.lease.want(action == "take")
            elif action == "clear_estop":
                with self.lock:
                    self.keyboard.joystick.estop = False
        if "stop" in actions or "estop" in actions:
            self.urgent.set()

    @property
    def mode(self) -> str:
        return "script" if self.script else "gamepad" if self.gamepad_source else "keyboard"

    # ----- the dashboard ----------------------------------------------------
    def map_points(self) -> list:
        points = [self.q0[:2]]
        duration = self.options.scenario.duration
        points += [self.loop.human.desired(t).q[:2] for t in np.linspace(0.0, duration, 41)]
        return points

    def view(self, frame: MapFrame, grid) -> DashboardView:
        tel = self.telemetry
        now = time.monotonic()
        with tel.lock:
            state, arrival = tel.state, tel.state_arrival
            view = DashboardView(
                title=f"sharedctl console · {self.options.robot_id} · {self.options.scenario.name}",
                mode=self.mode, state=state,
                state_age=None if arrival is None else now - arrival, states_received=tel.states,
                events=deque(tel.events, maxlen=6), trail=deque(tel.trail, maxlen=400), frame=frame, grid=grid,
                keys_help=KEYS_SCRIPT if self.script else KEYS_GAMEPAD if self.gamepad_source else KEYS_KEYBOARD,
                time_origin=tel.time_origin,
            )
        with self.lock:
            view.command = self.last_command
            origin = self.script_origin
        if self.script is not None and origin is not None:
            view.script_time = now - origin
        view.control = self.lease.status()
        if self.script is None and self.blind is not None:
            view.control += f" · HANDS-OFF: {self.blind}"
        return view

    # ----- the process ------------------------------------------------------
    def run(self, stop: StopFlag, interactive: bool, out=None) -> int:
        out = out if out is not None else sys.stdout
        opts = self.options
        start = time.monotonic()
        session = open_configured(opts.zenoh_config, opts.listen, opts.connect)
        live = pad_reader = None
        try:
            subscribers = [
                session.declare_subscriber(keys.state_key(opts.robot_id), self.telemetry.on_state),
                session.declare_subscriber(keys.events_key(opts.robot_id), self.telemetry.on_event),
            ]
            publisher = zenoh_qos.declare_publisher(session, keys.operator_cmd_key(opts.robot_id))
            sender = threading.Thread(target=self.sender, args=(publisher, stop), name="operator-sender", daemon=True)
            sender.start()
            leaser = threading.Thread(target=self.lease.run, args=(session, stop), name="operator-lease", daemon=True)
            leaser.start()
            if self.gamepad is not None:
                pad_reader = threading.Thread(target=self.gamepad.run, args=(stop, self.lock, self.on_gamepad),
                                              name="operator-gamepad", daemon=True)
                pad_reader.start()
            with KeyReader() if interactive else _NoKeys() as reader:
                if interactive:
                    live = self._start_live()
                frame, grid, grid_yaw = None, None, 0.0
                next_draw = 0.0
                while not stop.stopped:
                    now = time.monotonic()
                    self.ui_alive_at = now
                    if opts.duration is not None and now - start >= opts.duration:
                        break
                    typed = reader.read()
                    if typed:
                        self.on_keys(parse_keys(typed), now)
                    if live is not None and now >= next_draw:
                        frame, grid, grid_yaw = self._map(live, frame, grid, grid_yaw)
                        live.update(render(self.view(frame, grid)), refresh=True)
                        next_draw = now + REDRAW_PERIOD
                    stop.wait(0.02)
                stop.stop()
                self.urgent.set()                 # the sender ends now, not at its next tick
                if live is not None:
                    live.stop()
                    live = None
            # both are daemon threads; a lease query still waiting for a controller that is gone
            # ends when the session closes, so the console does not wait out its timeout here
            sender.join(timeout=0.2)
            leaser.join(timeout=0.2)
            self.lease.hand_back(session)         # control back to the controller now, not at the staleness
            for sub in subscribers:
                sub.undeclare()
            publisher.undeclare()
        finally:
            stop.stop()
            if live is not None:
                live.stop()
            session.close()
            if pad_reader is not None:
                pad_reader.join(timeout=0.5)      # waits ≤ 0.1 s for events, then sees the stop
            if self.gamepad is not None and (pad_reader is None or not pad_reader.is_alive()):
                self.gamepad.close()
        tel = self.telemetry
        last = "none" if tel.state is None else f"seq {tel.state.seq} t={tel.state.time:.2f} s"
        pad = "" if self.gamepad is None else f"; {self.gamepad.describe()}"
        print(f"sharedctl console: {self.mode} {opts.robot_id}: "
              f"sent {self.sent} commands in {time.monotonic() - start:.1f} s, received {tel.states} states "
              f"(last {last}), {tel.event_count} events, {tel.rejected} rejected; control {self.lease.status()}, "
              f"{self.lease.replies}/{self.lease.queries} lease queries answered{pad}", file=out, flush=True)
        return 0

    def _start_live(self):
        from rich.console import Console
        from rich.live import Live

        live = Live(console=Console(), screen=True, auto_refresh=False, transient=True)
        live.start()
        return live

    def _map(self, live, frame, grid, grid_yaw):
        """(Re)build the map when the screen size changes, the robot leaves it or the yaw turns."""
        size = live.console.size
        cols, rows = map_size(size.width, size.height)
        with self.telemetry.lock:
            state = self.telemetry.state
        yaw = 0.0 if state is None or len(state.q) < 3 else float(state.q[2])
        robot_out = state is not None and frame is not None and frame.cell(state.q[0], state.q[1]) is None
        if frame is None or (frame.cols, frame.rows) != (cols, rows) or robot_out:
            points = self.map_points() + ([] if state is None else [state.q[:2]])
            frame, grid = MapFrame.around(points, cols, rows), None
        if grid is None or abs(yaw - grid_yaw) > 0.1:
            grid, grid_yaw = background(self.loop.feasible, frame, yaw, self.q0), yaw
        return frame, grid, grid_yaw


def blind(now: float, ui_alive_at: float, state_arrival: float | None) -> str | None:
    """Why the operator cannot see at `now` (monotonic s), or None: the UI loop stalled, or telemetry is old."""
    if now - ui_alive_at > UI_STALE:
        return f"console UI frozen for {now - ui_alive_at:.1f} s"
    if state_arrival is None:
        return "no telemetry yet"
    if now - state_arrival > TELEMETRY_STALE:
        return f"telemetry {now - state_arrival:.1f} s old"
    return None


class _NoKeys:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def read(self) -> str:
        return ""
