"""The controller/arbiter daemon's loop: wheels → odometry → operator → shared controller → torques.

Every control period (500 Hz by default, `RateClock`) a tick reads (1, 2), steps (3, 4) and writes (5):
  1. latest wheel encoder estimates → odometry (q, q̇)                    (odometry.py)
  2. latest operator command → OperatorInput, with the staleness policy   (operator_input.py)
  3. the mode logic; `SharedController.step(state, q, q̇ or None, operator, dt, delay)` (sharedctl; None for
     `of`), `delay` the age (q, q̇) will have when the torques act (`prediction_delay`; 0 with --no-predict)
  4. τ = B(ψ)⁻¹ u_s (`OmniRobot.wheel_map`, in closed form), scaled down
     uniformly so that max|τ_j| ≤ the torque limit (the direction of u_s is kept)
  5. Set_Input_Torque to every axis as soon as computed (can_master.py), then the period's telemetry
     (telemetry_schedule.py);
then it reads CAN frames until `RECEIVE_MARGIN` before the clock's final spin, judging queued
operator commands on the way (frames of the last stretch, often the wheel estimates, are read at
the tick's start: reading them right up to the deadline let a slow stretch of the machine push
the reading past it). Timing (docs/performance.md): the next deadline is locked to `sensor_lead` after the
wheel estimates arrive (phase.py, on by default); the last `spin` before it is polled rather than
slept (`RateClock`); a tick whose estimates are late waits for them, briefly (`sensor_wait`);
operator commands wait in a Zenoh channel that the loop polls (command_intake.py: no Python
callback thread, so none can hold the GIL when the loop wakes); with `torque_at` a tick's torque
frames are held until that long after its deadline (time-triggered output: the hold polls the clock,
never sleeps; off by default, docs/performance.md); a warm-up step runs and
`gc.freeze()` is called, the first Heartbeat sent and the CAN frames queued since the bus opened are
read before the clock starts (they cost the first period 0.3–0.7 ms otherwise). After each tick the CAN
round-trip poll that is due goes out (can_master.py, round_trip.py: `--rtt-probe-rate`, 10 Hz by
default; its reply is read with the other frames). RobotState goes out at the telemetry
rate on the clock (captured, built and sent in three consecutive periods: telemetry_schedule.py),
events when something changes (rate-limited), a Heartbeat message at 1 Hz and a liveliness token for
as long as the daemon runs. The loop's statistics are an observer beside it (loop_stats.py), notified
at named points of each period; `run` returns its summary.

Modes: STARTING → ARMING (zero torque sent, waiting for CLOSED_LOOP heartbeats) → RUNNING → ESTOPPED,
and HELD. A controller arms only drives it has disarmed itself in this life: STARTING sends IDLE
to every axis (again every 0.1 s) until each has been heard idle, with its encoder reading; then
resume.py decides the start — from the checkpoint of a controller that died (checkpoint.py: the
pose carried forward by the odometry over the encoder increments since, HELD until an operator
takes control, a latched Estop still latched), from the scenario's pose (a first start or a
declared one: ARMING at once), or a refusal (HELD for good, and why). While running, the
checkpoint is written every 50 ms and at every Estop, so the next controller can do the same.
Estop (Estop frame to every axis, every tick for the first `ESTOP_BURST` and every 0.5 s after while
latched, no more torque commands) on: the operator's estop flag; wheel feedback older than
`feedback_timeout` while running; a loop that sent no torque for `silence_limit` (the backup's T_w less
`SILENCE_MARGIN`: a stall that may have let one drive's watchdog expire while the others were fed); an
axis reporting an error or leaving closed loop; a non-finite command. An operator command with
control_request "take" (and estop false) sent after the estop — or after the hold began — arms
the axes; a refused start arms never. HELD repeats IDLE every 0.5 s.

Operator authority: a Zenoh queryable on `…/control/lease` answers take/release requests, polled
by the loop like the commands (zenoh_links.py, lease_queries.py → lease.py); only the lease
holder's commands drive, an estop from anyone stops (operator_input.py); replayed, out-of-order
and stale messages are dropped (replay_guard.py). Every refusal is counted by reason (exit
summary, `rejection` events) and the total goes out as `link.rejected_messages`.
"""
from __future__ import annotations

import enum
import gc
import math
import threading
import time

import numpy as np

from sharedctl.protocol import keys
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.protocol.wire_types import Dims
from sharedctl.shared_controller import HISTORY, NonFiniteCommand, SharedController

from ..lifecycle import RateClock, poll_until
from .can_master import CanMaster
from .continuity import Continuity
from .daemon_config import DaemonConfig
from .lease import OperatorLease
from .loop_stats import LoopStats
from .odometry import WheelOdometry, oldest_feedback_age
from .phase import SensorPhaseLock, estimates_arrival
from .operator_input import OperatorInputPolicy
from .replay_guard import ReplayGuard
from .telemetry import EventLimiter, Link, robot_state
from .telemetry_schedule import TelemetrySchedule
from .zenoh_links import ControllerLinks

ROLE = "controller"
RECEIVE_SLICE = 5e-4    # s: the loop takes and judges operator commands at least this often between ticks
RECEIVE_MARGIN = 2e-4   # s: reading CAN frames stops this long before the clock's final spin (the rest: next tick)
MAX_DELAY = 0.1         # s: the largest delay predicted over (a longer one is cut to it; see `prediction_delay`)
REPEAT_INTERVAL = 0.5   # s: a latched Estop's frames, and a hold's IDLE, are sent again this often
STARTING_REPEAT = 0.1   # s: IDLE sent again this often until every axis has been heard idle
FOREIGN_REPEAT = 0.005  # s: while another master's commands keep coming, the Estop is sent again this often
ESTOP_BURST = 0.1       # s: after an Estop its frames go out every tick this long (a lost one must not leave a drive
#                         on its last torque until its watchdog), then every REPEAT_INTERVAL
SILENCE_MARGIN = 0.02   # s: torque frames lost around a stall that the silence rule allows for (`silence_limit`):
#                         ten periods, lost in a row with probability 1e-7 at 20 % loss


class Mode(enum.Enum):
    STARTING = "starting"   # IDLE sent to every axis; waiting to hear each one idle (module doc)
    ARMING = "arming"
    RUNNING = "running"
    HELD = "held"           # disarmed until an operator takes control; for good when the start was refused
    ESTOPPED = "estopped"


class ControllerDaemon:
    """One controller process's state; `run(stop)` is the loop."""

    def __init__(self, config: DaemonConfig, loop, q0, bus, session) -> None:
        self.config = config
        self.loop = loop
        self.model = loop.model
        if not hasattr(self.model, "wheel_torques"):
            raise ValueError("the controller daemon drives the omnidirectional robot (robot.kind = omni3)")
        self.controller = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference,
                                           loop.backup)
        self.output_feedback = loop.controller.observer is not None
        self.q0, self.theta_hat0 = tuple(float(x) for x in q0), loop.theta_hat0
        self.state = self.controller.initial_state(q0, loop.theta_hat0)
        self.dims = Dims(dof=self.model.n, n_theta=self.model.n_theta, n_wheels=3)
        self.odometry = WheelOdometry(self.model, q0)
        self.wheel_map = self.model.wheel_map   # τ = B(ψ)⁻¹ u in closed form, on floats (OmniRobot's WheelMap)
        trust = config.operators                  # who may command, by signature (security/signing.py), or None
        self.policy = OperatorInputPolicy(loop.human.kp, config.operator_timeout, self.dims,
                                          lease=OperatorLease(config.lease_expiry, config.lease_mode),
                                          guard=ReplayGuard(config.max_command_age, config.max_clock_skew),
                                          verify=trust and trust.verifier(keys.operator_cmd_key(config.robot_id),
                                                                          config.robot_id))
        self.lease_guard = ReplayGuard(config.max_command_age, config.max_clock_skew)   # lease queries' own
        self.master = CanMaster(bus, arm_timeout=config.arm_timeout, probe_rate=config.rtt_probe_rate)
        self.session = session
        self.lock = threading.Lock()
        self.links = ControllerLinks(session, config.robot_id, ROLE, self.policy, self.lease_guard, self.lock,
                                     EventLimiter(config.event_interval, ROLE), config.verbose,   # zenoh_links.py
                                     trust and trust.verifier(keys.lease_key(config.robot_id), config.robot_id))
        self.intake, self.apply_commands, self.emit = self.links.intake, self.links.apply_commands, self.links.emit
        self.ros2 = None                          # the ROS 2 node over rmw_zenoh (ros2_links.py), with --ros2
        if config.ros2_domain is not None:
            from .ros2_links import Ros2Links     # rosbags (the `ros2` extra) only then

            self.ros2 = Ros2Links(session, config.robot_id, config.ros2_domain, self.policy, config.twist_scale)
            self.links.extra_intakes.append(self.ros2.intake)
        self.mode = Mode.STARTING
        self.start_requested_at: float | None = None   # master clock: when IDLE went to every axis (`begin`)
        self.start_text = ""                            # what `resume.decide` decided
        self.refusal: str | None = None                 # set: arming is refused for this controller's life
        self.estop_reason = ""
        self.hold_take_mark = 0
        self.last_repeat_at = -math.inf
        self.continuity = Continuity(config)           # the previous life's checkpoint, this life's (continuity.py)
        self.foreign_seen = 0                           # the CAN master's foreign_commands already acted on
        self.period = 1.0 / config.rate
        self.max_delay = min(MAX_DELAY, HISTORY * self.period)   # the predictor keeps HISTORY periods of commands
        # a loop silent this long may have let a drive's watchdog (T_w, the backup's `hold`) expire while the frames
        # that fed the others got through: resuming would drive the robot on the wheels left, so it estops instead
        self.silence_limit = loop.backup.hold - SILENCE_MARGIN if loop.backup is not None else math.inf
        self.delay = 0.0                                         # s, the last `delay` passed to the step
        self.q = np.asarray(q0, float).copy()
        self.v = np.zeros_like(self.q)
        self.out = None
        self.u_s = np.zeros(self.model.n)
        self.tau = np.zeros(3)
        self.last_step_at: float | None = None
        self.estop_take_mark = 0
        self.estopped_at = -math.inf
        self.take_requests, self.current_command = 0, None   # the policy's, as read by the tick
        self.status, self.feedback_age = None, math.inf   # the operator input's status and the wheel estimates' age
        self.state_seq = 0
        self.started_at = time.monotonic()
        self.last_authority = None
        self.last_set_class = None
        self.lease_holder = None
        self.lease_since: float | None = None   # monotonic instant the holder was granted the lease
        self.last_hands_off_reason = None
        self.last_rejected = 0
        self.last_tick_at: float | None = None
        self.deadline: float | None = None       # the clock's deadline of the tick under way (None outside run)
        self.clock: RateClock | None = None      # the loop's clock, once `run` has started it (metrics.py reads it)
        self.realtime = False
        self.phase_lock = SensorPhaseLock(self.period, lead=config.sensor_lead) if config.sensor_sync else None
        self.stats = LoopStats(self.period, config.torque_at, frames=self.master, commands=self.intake)
        self.telemetry = TelemetrySchedule(
            config.telemetry_rate, self.period, self._capture_state, self.links.state_pub, self.links.alive_pub,
            self.dims, ROLE, config.robot_id,
            failed=lambda now, text: self.emit(now, "telemetry", "info", "warning", text),
            followers=() if self.ros2 is None else (self.ros2.send_odometry, self.ros2.send_authority))

    # ------------------------------------------------------------------- loop
    def run(self, stop) -> dict:
        """The loop until `stop` (or `duration`); returns the loop statistics' summary (loop_stats.py)."""
        config, stats = self.config, self.stats
        self.warm_up()
        gc.collect()
        gc.freeze()      # start-up objects (scenario, Zenoh, numpy) out of the collector's way: shorter pauses
        # the first (the publisher's first put is the slow one), before the clock
        self.telemetry.heartbeats(time.monotonic())
        self.master.receive_until(0.0)    # the frames queued since the bus opened: not the first period's work
        self.clock = clock = RateClock(self.period, spin=config.spin)
        t0 = stats.start()
        self.begin()
        ended = False      # stopped on purpose (stop flag, duration): the last checkpoint says so
        try:
            while not stop.stopped:
                reached, due, missed_before = time.monotonic(), clock.next, clock.missed
                lateness = clock.wait()
                self.deadline = clock.next - self.period
                stats.period_start(lateness, clock.missed - missed_before, reached <= due, reached)
                self.master.receive_until(0.0)    # what arrived during the margin and the spin (or a stall)
                self.await_estimates()
                now = time.monotonic()
                self.last_tick_at = now
                if config.duration is not None and now - t0 >= config.duration:
                    break
                self.tick(now)                    # read → step → write: the torque frames
                self.telemetry.publish_due(now)   # then the RobotState stage and the Heartbeat that are due
                self.save_checkpoint(now)         # when one is due
                stats.tick_done(now)
                self.master.probe_round_trip()    # the round-trip poll, if one is due: one frame, never a wait
                if self.phase_lock is not None and (arrival := estimates_arrival(self.master.estimates())) is not None:
                    clock.next += self.phase_lock.correction(clock.next, arrival)
                self.receive_until(clock.next - config.spin - RECEIVE_MARGIN)
                stats.period_end()
            ended = True
        finally:
            self.shutdown(ended)
        return stats.summary(clock.missed, {
            "frames_rx": self.master.rx_frames, "frames_tx": self.master.tx_frames,
            "foreign_commands": self.master.foreign_commands,
            "foreign_by_id": {f"0x{i:03X}": n for i, n in sorted(self.master.foreign.items())},
            "bad_frames": self.master.bad_frame_count,
            "implausible_estimates": sum(self.master.implausible_estimates.values()),
            "commands_accepted": self.policy.accepted, "rejections": dict(self.policy.rejections),
            "can_round_trip_ms": self.master.round_trip * 1e3, "rtt_probes": self.master.probe.counts(),
            "mode": self.mode.value, "start": self.start_text, "arming_refused": self.refusal,
            **self.continuity.summary(), **({} if self.ros2 is None else {"ros2": self.ros2.summary()})})

    def warm_up(self) -> None:
        """One control step and one RobotState built and encoded, all discarded, before the clock starts.

        The first run of each path (lazy imports, caches, the allocator's first arenas) costs
        milliseconds; without this, those are the loop's first deadlines. The step is a function of
        the state passed in (nothing is sent, no state is kept); the policy has no command yet."""
        try:
            with self.lock:
                operator, _ = self.policy.operator_input(time.monotonic(), self.q)
            _, out = self.controller.step(self.state, self.q, None if self.output_feedback else self.v, operator,
                                          self.period)
            self.wheel_map.wheel_torques(self.q, out.u_s)
            msg = robot_state(0, time.time(), self.q, self.v, out, self.loop.feasible, self.loop.sharing.bands,
                              np.zeros(3), out.u_s, False, None, Link(0.0, 0.0, math.inf, math.inf), out.theta_estimate)
            encode_message(msg, self.dims)
        except Exception:  # noqa: BLE001 — only a warm-up: the loop reports whatever this hit
            pass

    def await_estimates(self) -> None:
        """A synchronised tick in RUNNING mode whose period's wheel estimates have not all arrived yet (the
        drives sent late) reads frames for up to `sensor_wait` until they have: otherwise it would control
        with the previous period's, a period older. Only where the drives send once per control period
        (their measured interval within 1.5 periods): a loop faster than its sensors has ticks without new
        estimates by design. Counted by the statistics (`sensor_waits`, `sensor_waits_in_vain`)."""
        since = self.last_tick_at
        if self.phase_lock is None or self.config.sensor_wait <= 0 or since is None or self.mode is not Mode.RUNNING:
            return
        if self.master.estimates_since(since):
            return
        interval = self.master.estimate_interval()
        if interval is None or interval > 1.5 * self.period:
            return
        self.master.receive_until(self.master.clock() + self.config.sensor_wait,
                                  stop_when=lambda: self.master.estimates_since(since))
        self.stats.sensor_wait(arrived=self.master.estimates_since(since))

    def receive_until(self, deadline: float) -> None:
        """CAN frames until `deadline`, applying queued operator commands every `RECEIVE_SLICE` on the way
        (so that judging them rarely falls into the next tick)."""
        while True:
            self.master.receive_until(min(deadline, time.monotonic() + RECEIVE_SLICE))
            with self.lock:
                self.apply_commands()
            if time.monotonic() >= deadline:
                return

    def tick(self, now: float) -> None:
        """One period's control: read (wheel estimates, operator commands) → step (mode logic, control law,
        torque limit) → write (the torque frames). The period's telemetry follows in `run`."""
        operator = self.read(now)
        tau = self.step(now, operator)
        if tau is not None:
            self.write(now, tau)

    # ------------------------------------------------------------------- read
    def read(self, now: float):
        """The wheel estimates → odometry (q, q̇) and the age of the oldest; the operator commands that arrived
        → this period's `OperatorInput`. What changed on the way (CAN events, rejections, the hands-off
        reason, the lease) is reported as events."""
        estimates = self.master.estimates()
        self.q, self.v = self.odometry.update(estimates)
        self.feedback_age = oldest_feedback_age(estimates, now)
        if self.odometry.uncertainty > self.config.pose_tolerance and self.refusal is None:
            self.pose_lost(now)
        for ev in self.master.take_events():
            self.emit(now, f"can:{ev.text[:8]}", ev.kind, ev.severity, ev.text)
        with self.lock:
            self.policy.pose = self.q               # what an operator's wish is judged against (admission.py)
            self.apply_commands()
            operator, status = self.policy.operator_input(now, self.q)
            self.take_requests, self.current_command = self.policy.take_requests, self.policy.current
            rejected = self.policy.rejected
            rejections = dict(self.policy.rejections) if rejected != self.last_rejected else None
            lease_changes = self.policy.lease.take_changes()
            self.lease_holder, self.lease_since = self.policy.lease.holder_id, self.policy.lease.holder_since
        self.status = status
        if rejections is not None:
            self.last_rejected = rejected
            self.emit(now, "rejection", "rejection", "warning", f"operator messages rejected so far: {rejections}")
        if status.reason != self.last_hands_off_reason:
            self.last_hands_off_reason = status.reason
            self.emit(now, "operator", "info", "info", f"operator input: {status.reason}")
        for change in lease_changes:
            self.emit(now, f"lease:{change.cause}", "lease_change", "info",
                      f"lease {change.cause}: control {change.before or 'free'} -> {change.after or 'free'}")
        return operator

    # ------------------------------------------------------------------- step
    def step(self, now: float, operator):
        """The mode logic (module doc); while RUNNING, the control step. Returns the wheel torques to write,
        None if there are none: an estop sends its Estop frames at once, arming its zero torques."""
        if self.master.foreign_commands > self.foreign_seen:
            self.foreign_seen = self.master.foreign_commands
            if self.mode not in (Mode.ESTOPPED, Mode.STARTING):
                self.estop(now, f"foreign CAN master: {self.master.last_foreign}")
            elif self.mode is Mode.ESTOPPED and now - self.last_repeat_at >= FOREIGN_REPEAT:
                self.master.estop_all()         # undo what the other master may have re-armed
                self.last_repeat_at = now
        if self.status.estop_requested and self.mode not in (Mode.ESTOPPED, Mode.STARTING):
            self.estop(now, "estop requested by the operator")
        if self.mode is Mode.STARTING:
            self.u_s, self.tau = np.zeros(self.model.n), np.zeros(3)
            if self.master.heard_idle_since(self.start_requested_at):
                self.start(now)
            elif now - self.last_repeat_at >= STARTING_REPEAT:
                self.master.idle_all()
                self.last_repeat_at = now
                waiting = self.master.not_idle(self.start_requested_at)
                self.emit(now, "starting", "info", "info", "starting: waiting to hear every axis idle, with its "
                                                           f"encoder reading (silent or armed: {waiting})")
        elif self.mode is Mode.HELD:
            self.u_s, self.tau = np.zeros(self.model.n), np.zeros(3)
            if now - self.last_repeat_at >= REPEAT_INTERVAL:
                self.master.idle_all()
                self.last_repeat_at = now
            if self.operator_took(self.hold_take_mark):
                self.hold_take_mark = self.take_requests
                if self.refusal is None:
                    self.rearm(now, "armed by the operator's take after the start")
                else:
                    self.emit(now, "refused", "fault", "critical", self.refusal)
        elif self.mode is Mode.ARMING:
            self.u_s, self.tau = np.zeros(self.model.n), np.zeros(3)
            self.master.send_torques(self.tau)   # feeds the watchdogs as soon as an axis closes its loop
            if self.master.arming_done(now):
                self.mode = Mode.RUNNING
                self.last_step_at = None
                self.emit(now, "armed", "info", "info", f"axes armed (attempt {self.master.arm_attempts})")
        elif self.mode is Mode.RUNNING:
            faulted = self.master.faulted_axes()
            silent = 0.0 if self.last_step_at is None else now - self.last_step_at
            if self.feedback_age > self.config.feedback_timeout:
                self.estop(now, f"CAN feedback lost: oldest wheel estimate {self.feedback_age * 1e3:.0f} ms old")
            elif silent >= self.silence_limit:
                self.estop(now, f"no torque sent for {silent * 1e3:.0f} ms (the loop stalled): a drive's watchdog "
                                "may have expired while the others drive on")
            elif faulted:
                self.estop(now, f"axes {faulted} left closed loop or report errors")
            else:
                self.master.keep_torque_mode(now)   # a drive that lost its Set_Controller_Mode ignores torques
                return self.control(now, operator)
        elif self.mode is Mode.ESTOPPED:
            self.u_s, self.tau = np.zeros(self.model.n), np.zeros(3)
            burst = now - self.estopped_at < ESTOP_BURST
            if now - self.last_repeat_at >= (0.5 * self.period if burst else REPEAT_INTERVAL):   # burst: every tick
                self.master.estop_all()          # a drive that missed the first (or restarted since) gets it again
                self.last_repeat_at = now
            if self.operator_took(self.estop_take_mark):
                self.estop_take_mark = self.take_requests
                if self.refusal is not None:
                    self.emit(now, "refused", "fault", "critical", self.refusal)
                    return None
                with self.lock:
                    self.policy.clear_estop()
                self.estop_reason = ""
                self.rearm(now, "estop cleared by the operator (take): re-arming", "estop_cleared")
        return None

    def operator_took(self, mark: int) -> bool:
        """An in-band take (estop false) since `mark`, with fresh wheel feedback."""
        return (self.take_requests > mark and self.current_command is not None and not self.current_command.estop
                and self.feedback_age <= self.config.feedback_timeout)

    def rearm(self, now: float, text: str, kind: str = "info") -> None:
        self.state = self.controller.initial_state(self.q, self.state.theta_hat)
        self.master.reset_arming()
        self.master.request_arming()
        self.mode = Mode.ARMING
        self.emit(now, f"rearm:{kind}", kind, "info", text)

    # ------------------------------------------------------------------ start
    def begin(self) -> None:
        """IDLE to every axis: the start (STARTING) waits to hear each one idle before anything else."""
        self.master.idle_all()
        self.start_requested_at = self.master.clock()
        self.mode = Mode.STARTING

    def start(self, now: float) -> None:
        """Every axis heard idle since `begin`: where the robot is and what may follow (resume.py)."""
        estimates = self.master.estimates()
        decision = self.continuity.decide(self.q0, [e.pos_turns for e in estimates],
                                          [self.master.axes[n].error for n in self.master.nodes])
        self.odometry.resume(decision.q, decision.wheel_turns)
        self.q, self.v = self.odometry.update(estimates)
        theta = decision.theta_hat
        if theta is None or len(theta) != self.model.n_theta:
            theta = self.theta_hat0
        self.state = self.controller.initial_state(self.q, theta)
        self.start_text = decision.text
        self.hold_take_mark = self.estop_take_mark = self.take_requests
        self.last_repeat_at = -math.inf
        self.emit(now, "start", "info", "critical" if decision.action == "refuse" else "info",
                  f"{decision.text}; pose ({', '.join(f'{x:.3f}' for x in self.q)})")
        self.refusal = decision.text if decision.action == "refuse" else None
        if decision.action == "arm" and not self.status.estop_requested:
            self.master.reset_arming()
            self.master.request_arming()
            self.mode = Mode.ARMING
        elif decision.action == "estop" or self.status.estop_requested or self.master.foreign_commands:
            reason = self.continuity.saved_estop_reason or (
                "estop requested by the operator" if self.status.estop_requested
                else f"foreign CAN master: {self.master.last_foreign}" if self.master.foreign_commands
                else "a drive reports an Estop")
            self.estop(now, f"latched at start: {reason}")
        else:
            self.mode = Mode.HELD

    def pose_lost(self, now: float) -> None:
        """A drive's encoder took a new origin while its wheel turned (odometry.py): the pose may be off by more
        than `pose_tolerance`. Stop, and arm no more in this life."""
        self.refusal = (f"arming refused: a drive's encoder took a new origin while its wheel turned, so the pose "
                        f"may be off by up to {self.odometry.uncertainty * 100:.1f} cm. Restart the controller with "
                        "--pose scenario once the robot stands at the scenario's start pose")
        if self.mode in (Mode.ARMING, Mode.RUNNING):
            self.estop(now, "the pose is no longer known (a drive's encoder restarted while its wheel turned)")
        self.emit(now, "refused", "fault", "critical", self.refusal)

    def save_checkpoint(self, now: float, force: bool = False, ended: bool = False) -> None:
        """The checkpoint (checkpoint.py), when due or forced; never before the start is decided, nor after a
        refused one (its pose is no evidence)."""
        if self.mode is Mode.STARTING or self.refusal is not None or not (force or self.continuity.due(now)):
            return
        baseline = self.odometry.baseline()      # (q, the encoder readings q was integrated up to)
        if baseline is None:
            return
        failure = self.continuity.save(now, *baseline, self.state.theta_hat, estop=self.mode is Mode.ESTOPPED,
                                       reason=self.estop_reason, armed=self.mode is Mode.RUNNING, ended=ended)
        if failure is not None:
            self.emit(now, "checkpoint", "fault", "error", failure)

    def control(self, now: float, operator):
        """`SharedController.step`, τ = B(ψ)⁻¹u_s scaled down uniformly to the torque limit; None (and zero
        torque, then an estop) on a non-finite command."""
        # the laws integrate over at most four periods; the predictor runs the last command over the time it acted
        elapsed = self.period if self.last_step_at is None else min(max(now - self.last_step_at, 0.0), self.max_delay)
        dt = min(elapsed, 4 * self.period)
        self.last_step_at = now
        self.delay = self.prediction_delay(now) if self.config.predict else 0.0
        try:
            self.state, out = self.controller.step(self.state, self.q, None if self.output_feedback else self.v,
                                                   operator, dt, self.delay, elapsed)
            u_s = out.u_s.tolist() if isinstance(out.u_s, np.ndarray) else out.u_s
            tau = self.wheel_map.wheel_torques(self.q, u_s)
            if not all(math.isfinite(t) for t in tau):
                raise NonFiniteCommand("non-finite wheel torque")
        except NonFiniteCommand as exc:
            self.tau, self.u_s = np.zeros(3), np.zeros(self.model.n)
            self.master.send_torques(self.tau)
            self.estop(now, f"non-finite command: {exc}")
            return None
        peak = max(abs(t) for t in tau)
        if peak > self.config.torque_limit:
            scale = self.config.torque_limit / peak
            tau = tuple(t * scale for t in tau)
            self.stats.torque_limited()
        self.out, self.u_s, self.tau = out, out.u_s, np.array(tau)
        self.stats.torques_ready(now)
        return tau

    def prediction_delay(self, now: float) -> float:
        """How old the (q, q̇) read at `now` will be when this tick's torques act (s), for the step's predictor:

            L = feedback age + CAN round trip + hold,

        the feedback age from the estimates' arrival to `now` (odometry.oldest_feedback_age); the round trip
        (can_master.py; 0 until measured) for the two legs the arrival times cannot show — the estimates'
        transit from the drives and the torques' transit to them, with the drives' turnaround — whose sum it
        measures whichever leg a delay is on; the hold until `torque_at` after the deadline, when the torques
        are held (`write`). Cut to `max_delay`: MAX_DELAY, or fewer if the controller's command history
        (HISTORY periods) is shorter; beyond it the prediction has no commands to run on."""
        round_trip = self.master.round_trip
        hold = 0.0
        if self.config.torque_at > 0.0:
            hold = max((now if self.deadline is None else self.deadline) + self.config.torque_at - now, 0.0)
        delay = self.feedback_age + (round_trip if math.isfinite(round_trip) else 0.0) + hold
        return min(delay, self.max_delay)

    def estop(self, now: float, reason: str) -> None:
        self.master.estop_all()
        self.last_repeat_at = self.estopped_at = now
        self.tau, self.u_s = np.zeros(3), np.zeros(self.model.n)
        self.mode = Mode.ESTOPPED
        self.estop_reason = reason
        self.stats.estop()
        with self.lock:
            self.estop_take_mark = self.policy.take_requests
        self.emit(now, f"estop:{reason[:12]}", "estop", "critical", f"ESTOP: {reason}")
        self.save_checkpoint(now, force=True)      # the latch outlives this process

    # ------------------------------------------------------------------ write
    def write(self, now: float, tau) -> None:
        """The torque frames, as soon as computed or, with `torque_at`, that long after the deadline (the hold
        polls the clock); then the events of what the step changed (set class, authority)."""
        if self.config.torque_at > 0.0:
            poll_until((now if self.deadline is None else self.deadline) + self.config.torque_at)
        self.master.send_torques(tau)
        self.stats.torques_sent(now, self.feedback_age)
        out = self.out
        if out.set_class != self.last_set_class:
            if self.last_set_class is not None:
                self.emit(now, "set", "set_transition", "info",
                          f"set {self.last_set_class.name.lower()} -> {out.set_class.name.lower()}")
            self.last_set_class = out.set_class
        if out.authority != self.last_authority:
            if self.last_authority is not None:
                self.emit(now, "authority", "authority_change", "info",
                          f"authority {self.last_authority.name.lower()} -> {out.authority.name.lower()}")
            self.last_authority = out.authority

    def _capture_state(self, now: float) -> tuple:
        """`telemetry.robot_state`'s arguments for this period (stage 0 of a RobotState: telemetry_schedule.py)."""
        status = self.status
        link = Link(
            latency=status.latency, loss_fraction=status.loss_fraction,
            staleness=status.staleness if math.isfinite(status.staleness) else now - self.started_at,
            can_feedback_age=self.feedback_age if math.isfinite(self.feedback_age) else now - self.started_at,
            rejected=self.last_rejected,
        )
        out = self.out
        v_used = out.v_used if out is not None and self.mode is Mode.RUNNING else self.v
        if out is not None:
            out.q_r                     # noqa: B018 — worked out here, in this stage's period (lazy, then kept)
        self.state_seq += 1
        wall = time.time()
        since = None if self.lease_since is None else self.lease_since + (wall - time.monotonic())   # wall clock
        return (self.state_seq, wall, self.q, v_used, out, self.loop.feasible, self.loop.sharing.bands,
                self.tau, self.u_s, self.mode in (Mode.ESTOPPED, Mode.HELD), self.lease_holder, link,
                out.theta_estimate if out is not None else self.state.theta_hat, since)

    # --------------------------------------------------------------- shutdown
    def shutdown(self, ended: bool = True) -> None:
        """Zero torque, then IDLE to every axis (twice: a lost frame must not leave an axis armed); the last
        checkpoint, `ended` when the stop was on purpose (a controller that failed is resumed from it)."""
        self.tau, self.u_s = np.zeros(3), np.zeros(self.model.n)
        for _ in range(2):
            self.master.send_torques(self.tau)
            self.master.idle_all()
        self.save_checkpoint(time.monotonic(), force=True, ended=ended)
        self.continuity.close()             # a failed controller's last offer written too
        self.emit(time.monotonic(), "shutdown", "info", "info", "controller stopping: zero torque, axes IDLE")
