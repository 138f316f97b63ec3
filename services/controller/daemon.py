"""The controller/arbiter daemon's loop: wheels → odometry → operator → shared controller → torques.

Every control period (500 Hz by default, `RateClock`):
  1. latest wheel encoder estimates → odometry (q, q̇)                    (odometry.py)
  2. latest operator command → OperatorInput, with the staleness policy   (operator_input.py)
  3. `SharedController.step(state, q, q̇ or None, operator, dt)`          (sharedctl; None for `of`)
  4. τ = B(ψ)⁻¹ u_s (`OmniRobot.wheel_torques`, in closed form: wheel_kinematics.py), scaled down
     uniformly so that max|τ_j| ≤ the torque limit (the direction of u_s is kept), Set_Input_Torque
     to every axis                                                         (can_master.py)
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
read before the clock starts (they cost the first period 0.3–0.7 ms otherwise). RobotState goes out at the telemetry
rate on the clock (captured, built and sent in three consecutive periods: `telemetry`), events when
something changes (rate-limited), a Heartbeat message at 1 Hz and a
liveliness token for as long as the daemon runs.

Modes: ARMING (zero torque sent, waiting for CLOSED_LOOP heartbeats) → RUNNING → ESTOPPED.
Estop (Estop frame to every axis, no more torque commands, latched) on: the operator's estop
flag; wheel feedback older than `feedback_timeout` while running; an axis reporting an error
or leaving closed loop; a non-finite command. An operator command with control_request
"take" (and estop false) sent after the estop re-arms the axes.

Operator authority: a Zenoh queryable on `…/control/lease` answers take/release requests
(lease_queries.py → lease.py); only the lease holder's commands drive, an estop from anyone
stops (operator_input.py); replayed, out-of-order and stale messages are dropped
(replay_guard.py). Every refusal is counted by reason (summary line, `rejection` events) and
the total goes out as `link.rejected_messages`.
"""
from __future__ import annotations

import enum
import gc
import math
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from sharedctl.protocol import keys
from sharedctl.protocol.messages import Heartbeat
from sharedctl.protocol.msgpack_codec import encode_message
from sharedctl.protocol.wire_types import Dims
from sharedctl.shared_controller import NonFiniteCommand, SharedController

from ..lifecycle import RateClock, Schedule, poll_until
from . import command_intake, lease_queries
from .can_master import CanMaster
from .command_intake import CommandIntake
from .lease import DEFAULT_EXPIRY, LeaseMode, OperatorLease
from .loop_summary import LatenessHistogram, MissCauses, Summary
from .odometry import WheelOdometry, oldest_feedback_age
from .phase import SensorPhaseLock, estimates_arrival
from .operator_input import OperatorInputPolicy
from .replay_guard import DEFAULT_MAX_AGE, ReplayGuard
from .telemetry import EventLimiter, Link, robot_state
from .wheel_kinematics import WheelKinematics

ROLE = "controller"
RECEIVE_SLICE = 5e-4          # s: the loop takes and judges operator commands at least this often between ticks

TELEMETRY_STAGES = 3         # a RobotState is captured, built and sent in three consecutive periods (telemetry_stage)
RECEIVE_MARGIN = 2e-4         # s: reading CAN frames stops this long before the clock's final spin (the rest: next tick)


class Mode(enum.Enum):
    ARMING = "arming"
    RUNNING = "running"
    ESTOPPED = "estopped"


@dataclass
class DaemonConfig:
    robot_id: str = "robot1"
    rate: float = 500.0                 # Hz, control loop
    telemetry_rate: float = 50.0        # Hz, RobotState
    torque_limit: float = 60.0          # N·m per wheel (the simulated drive's limit)
    feedback_timeout: float = 0.05      # s: wheel feedback older than this (once armed) → estop
    operator_timeout: float = 0.3       # s: operator silence → hands-off
    arm_timeout: float = 0.5            # s per arming attempt
    duration: float | None = None       # s; None: until SIGINT/SIGTERM
    event_interval: float = 1.0         # s between events of one topic
    verbose: bool = True                # warnings and errors to stderr
    realtime: bool = False              # the loop thread asks for SCHED_FIFO (priority.py)
    sensor_sync: bool = True            # lock the tick phase to the wheel estimates' arrival (phase.py)
    sensor_lead: float = 2.5e-4         # s after the estimates' arrival at which a synchronised tick starts
    sensor_wait: float = 5e-4           # s a synchronised tick waits, at most, for its period's estimates (0: never)
    spin: float = 1e-4                  # s before each deadline polled instead of slept (lifecycle.RateClock)
    torque_at: float = 0.0              # s after its deadline at which a tick sends its torques (0: once computed)
    lease_mode: str = LeaseMode.IMPLICIT  # implicit: a command takes a free lease; explicit: only a take (lease.py)
    lease_expiry: float = DEFAULT_EXPIRY  # s without commands/takes from the holder → lease free
    max_command_age: float = DEFAULT_MAX_AGE  # s later than the session's best delivery → stale (replay_guard.py)
    max_clock_skew: float | None = None   # s, |receive wall − send_time| bound; None: hosts not synchronised


class ControllerDaemon:
    """One controller process's state; `run(stop)` is the loop."""

    def __init__(self, config: DaemonConfig, loop, q0, bus, session) -> None:
        self.config = config
        self.loop = loop
        self.model = loop.model
        if not hasattr(self.model, "wheel_torques"):
            raise ValueError("the controller daemon drives the omnidirectional robot (robot.kind = omni3)")
        self.controller = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference)
        self.output_feedback = loop.controller.observer is not None
        self.state = self.controller.initial_state(q0, loop.theta_hat0)
        self.dims = Dims(dof=self.model.n, n_theta=self.model.n_theta, n_wheels=3)
        self.odometry = WheelOdometry(self.model, q0)
        self.kinematics = WheelKinematics.for_model(self.model)   # τ = B(ψ)⁻¹ u in closed form
        self.policy = OperatorInputPolicy(loop.human.kp, config.operator_timeout, self.dims,
                                          lease=OperatorLease(config.lease_expiry, config.lease_mode),
                                          guard=ReplayGuard(config.max_command_age, config.max_clock_skew))
        self.lease_guard = ReplayGuard(config.max_command_age, config.max_clock_skew)   # lease queries' own
        self.master = CanMaster(bus, arm_timeout=config.arm_timeout)
        self.session = session
        self.events = EventLimiter(config.event_interval, ROLE)
        self.lock = threading.Lock()
        self.mode = Mode.ARMING
        self.period = 1.0 / config.rate
        self.q = np.asarray(q0, float).copy()
        self.v = np.zeros_like(self.q)
        self.out = None
        self.u_s = np.zeros(self.model.n)
        self.tau = np.zeros(3)
        self.last_step_at: float | None = None
        self.estop_take_mark = 0
        self.estops = 0
        self.saturated = 0
        self.state_seq = 0
        self._state_capture: tuple | None = None     # a RobotState between its stages (telemetry_stage)
        self._state_message = None
        self._state_stage: int | None = None        # the stage the next period runs, None: none under way
        self.state_schedule = Schedule(config.telemetry_rate)   # on the loop's clock (`telemetry`)
        self.heartbeat_schedule = Schedule(1.0)
        self.heartbeat_seq = 0
        self.started_at = time.monotonic()
        self.last_authority = None
        self.last_set_class = None
        self.lease_holder = None
        self.last_hands_off_reason = None
        self.last_rejected = 0
        self.histogram = LatenessHistogram()     # tick lateness (jitter)
        self.compute = LatenessHistogram()       # tick compute time (control + telemetry)
        self.torque_out = LatenessHistogram()    # tick start → Set_Input_Torque frames handed to the bus
        self.torque_ready = LatenessHistogram()  # tick start → torques computed (before `torque_at` holds them)
        self.sensor_to_torque = LatenessHistogram()   # arrival of the oldest estimate a tick used → its torque frames sent
        self.loop_cpu = LatenessHistogram()      # the loop thread's CPU time per period, outside the clock's wait
        self.late = 0
        self.miss_causes = MissCauses()
        self.sensor_waits = 0                    # ticks that waited for their period's wheel estimates
        self.sensor_wait_timeouts = 0            # … and started without them, after `sensor_wait`
        self.last_tick_at: float | None = None
        self.deadline: float | None = None       # the clock's deadline of the tick under way (None outside run)
        self.realtime = False
        self.phase_lock = SensorPhaseLock(self.period, lead=config.sensor_lead) if config.sensor_sync else None
        self._declare(session)

    # ------------------------------------------------------------------ Zenoh
    def _declare(self, session) -> None:
        robot = self.config.robot_id
        self.state_pub = session.declare_publisher(keys.state_key(robot))
        self.event_pub = session.declare_publisher(keys.events_key(robot))
        self.alive_pub = session.declare_publisher(keys.alive_key(robot, ROLE))
        self.token = session.liveliness().declare_token(keys.alive_key(robot, ROLE))
        self.subscriber = session.declare_subscriber(keys.operator_cmd_key(robot), command_intake.channel())
        self.intake = CommandIntake(self.subscriber, self.policy)
        self.queryable = session.declare_queryable(keys.lease_key(robot), self._on_lease_query)

    def apply_commands(self) -> None:
        """The operator commands that arrived, judged in arrival order (caller holds `lock`).

        Called by the loop between CAN frames and before each tick, and before a lease query is
        answered, so a take or release is judged after every command that arrived before it."""
        self.intake.apply()

    def _on_lease_query(self, query) -> None:
        """Zenoh callback thread: take/release control (lease_queries.py); every query gets a reply."""
        try:
            payload = query.payload.to_bytes() if query.payload is not None else b""
        except Exception:  # noqa: BLE001
            payload = b""
        with self.lock:
            self.apply_commands()
            reply = lease_queries.answer(payload, self.policy.lease, self.lease_guard, self.policy.rejections,
                                         time.monotonic(), time.time())
        try:
            query.reply(keys.lease_key(self.config.robot_id), encode_message(reply))
        except Exception as exc:  # noqa: BLE001 — a vanished querier must not stop anything
            print(f"sharedctl controller: lease reply not sent: {exc}", file=sys.stderr)

    def undeclare(self) -> None:
        for entity in (self.subscriber, self.queryable, self.token, self.state_pub, self.event_pub, self.alive_pub):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 — closing anyway
                pass

    def emit(self, now: float, topic: str, kind: str, severity: str, text: str) -> None:
        event = self.events.make(now, time.time(), topic, kind, severity, text)
        if event is None:
            return
        if self.config.verbose and severity in ("warning", "error", "critical"):
            print(f"sharedctl controller: {severity}: {event.text}", file=sys.stderr, flush=True)
        try:
            self.event_pub.put(encode_message(event))
        except Exception as exc:  # noqa: BLE001 — telemetry must not stop the loop
            print(f"sharedctl controller: event not sent: {exc}", file=sys.stderr)

    # ------------------------------------------------------------------- loop
    def run(self, stop) -> Summary:
        config = self.config
        self.warm_up()
        gc.collect()
        gc.freeze()      # start-up objects (scenario, Zenoh, numpy) out of the collector's way: shorter pauses
        self.heartbeats(time.monotonic())  # the first (the publisher's first put is the slow one), before the clock
        self.master.receive_until(0.0)    # the frames queued since the bus opened: not the first period's work
        clock = RateClock(self.period, spin=config.spin)
        cpu0, t0 = time.process_time(), time.monotonic()
        self.master.request_arming()
        ticks = 0
        period_cpu, period_work = 0.0, (0, 0)
        try:
            while not stop.stopped:
                reached, due, missed_before = time.monotonic(), clock.next, clock.missed
                lateness = clock.wait()
                self.deadline = clock.next - self.period
                cpu_at_tick = time.thread_time()
                self.histogram.add(lateness)
                late = lateness > 0.5 * self.period
                self.late += late
                misses = clock.missed - missed_before + late
                if misses and ticks:      # (the median's cumulative sum only for a tick that missed)
                    self.miss_causes.note(misses, reached <= due, period_cpu, self.loop_cpu.quantile(0.5), period_work,
                                          at=reached - t0)
                work_at_tick = (self.master.rx_frames, self.intake.taken)
                self.master.receive_until(0.0)    # what arrived during the margin and the spin (or a stall)
                self.await_estimates()
                now = time.monotonic()
                self.last_tick_at = now
                if config.duration is not None and now - t0 >= config.duration:
                    break
                self.tick(now)
                self.telemetry(now)
                self.heartbeats(now)
                ticks += 1
                self.compute.add(time.monotonic() - now)
                if self.phase_lock is not None and (arrival := estimates_arrival(self.master.estimates())) is not None:
                    clock.next += self.phase_lock.correction(clock.next, arrival)
                self.receive_until(clock.next - config.spin - RECEIVE_MARGIN)
                period_cpu = time.thread_time() - cpu_at_tick
                period_work = (self.master.rx_frames - work_at_tick[0], self.intake.taken - work_at_tick[1])
                self.loop_cpu.add(period_cpu)
        finally:
            self.shutdown()
        elapsed = time.monotonic() - t0
        cpu = time.process_time() - cpu0
        return Summary(
            ticks=ticks, elapsed=elapsed, rate=ticks / elapsed if elapsed > 0 else 0.0, missed=clock.missed,
            late=self.late, jitter_p50_ms=self.histogram.quantile(0.5) * 1e3,
            jitter_p99_ms=self.histogram.quantile(0.99) * 1e3, jitter_max_ms=self.histogram.max * 1e3,
            cpu_percent=100.0 * cpu / elapsed if elapsed > 0 else 0.0,
            compute_p50_ms=self.compute.quantile(0.5) * 1e3, compute_p99_ms=self.compute.quantile(0.99) * 1e3,
            torque_out_p50_ms=self.torque_out.quantile(0.5) * 1e3, torque_out_p99_ms=self.torque_out.quantile(0.99) * 1e3,
            torque_ready_p50_ms=self.torque_ready.quantile(0.5) * 1e3,
            torque_ready_p99_ms=self.torque_ready.quantile(0.99) * 1e3, torque_at_ms=config.torque_at * 1e3,
            loop_cpu_p50_ms=self.loop_cpu.quantile(0.5) * 1e3, loop_cpu_p99_ms=self.loop_cpu.quantile(0.99) * 1e3,
            sensor_to_torque_p50_ms=self.sensor_to_torque.quantile(0.5) * 1e3,
            sensor_to_torque_p99_ms=self.sensor_to_torque.quantile(0.99) * 1e3,
            sensor_waits=self.sensor_waits, sensor_wait_timeouts=self.sensor_wait_timeouts,
            misses_woke_late=self.miss_causes.woke_late, misses_not_run=self.miss_causes.not_run,
            misses_working=self.miss_causes.working, working_cpu_p50_ms=self.miss_causes.working_cpu_p50() * 1e3,
            working_frames_p50=self.miss_causes.working_work_p50()[0],
            working_commands_p50=self.miss_causes.working_work_p50()[1], miss_times=tuple(self.miss_causes.times),
            frames_rx=self.master.rx_frames,
            frames_tx=self.master.tx_frames, bad_frames=self.master.bad_frame_count,
            implausible_estimates=sum(self.master.implausible_estimates.values()),
            commands_accepted=self.policy.accepted, rejections=dict(self.policy.rejections), estops=self.estops,
            saturated=self.saturated, mode=self.mode.value,
        )

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
            self.kinematics.wheel_torques(self.q, out.u_s)
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
        estimates by design. Counted in `sensor_waits` / `sensor_wait_timeouts`."""
        since = self.last_tick_at
        if self.phase_lock is None or self.config.sensor_wait <= 0 or since is None or self.mode is not Mode.RUNNING:
            return
        if self.master.estimates_since(since):
            return
        interval = self.master.estimate_interval()
        if interval is None or interval > 1.5 * self.period:
            return
        self.sensor_waits += 1
        self.master.receive_until(self.master.clock() + self.config.sensor_wait,
                                  stop_when=lambda: self.master.estimates_since(since))
        if not self.master.estimates_since(since):
            self.sensor_wait_timeouts += 1

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
        estimates = self.master.estimates()
        self.q, v = self.odometry.update(estimates)
        self.v = v
        feedback_age = oldest_feedback_age(estimates, now)
        for ev in self.master.take_events():
            self.emit(now, f"can:{ev.text[:8]}", ev.kind, ev.severity, ev.text)
        with self.lock:
            self.apply_commands()
            operator, status = self.policy.operator_input(now, self.q)
            take_requests = self.policy.take_requests
            current = self.policy.current
            rejected = self.policy.rejected
            rejections = dict(self.policy.rejections)
            lease_changes = self.policy.lease.take_changes()
            self.lease_holder = self.policy.lease.holder_id
        self.status = status
        self.feedback_age = feedback_age
        if rejected != self.last_rejected:
            self.last_rejected = rejected
            self.emit(now, "rejection", "rejection", "warning", f"operator messages rejected so far: {rejections}")
        if status.reason != self.last_hands_off_reason:
            self.last_hands_off_reason = status.reason
            self.emit(now, "operator", "info", "info", f"operator input: {status.reason}")
        for change in lease_changes:
            self.emit(now, f"lease:{change.cause}", "lease_change", "info",
                      f"lease {change.cause}: control {change.before or 'free'} -> {change.after or 'free'}")

        if status.estop_requested and self.mode is not Mode.ESTOPPED:
            self.estop(now, "estop requested by the operator")
        if self.mode is Mode.ARMING:
            self.u_s, self.tau = np.zeros(self.model.n), np.zeros(3)
            self.master.send_torques(self.tau)   # feeds the watchdogs as soon as an axis closes its loop
            if self.master.arming_done(now):
                self.mode = Mode.RUNNING
                self.last_step_at = None
                self.emit(now, "armed", "info", "info", f"axes armed (attempt {self.master.arm_attempts})")
        elif self.mode is Mode.RUNNING:
            faulted = self.master.faulted_axes()
            if feedback_age > self.config.feedback_timeout:
                self.estop(now, f"CAN feedback lost: oldest wheel estimate {feedback_age * 1e3:.0f} ms old")
            elif faulted:
                self.estop(now, f"axes {faulted} left closed loop or report errors")
            else:
                self.control(now, operator)
        elif self.mode is Mode.ESTOPPED:
            self.u_s, self.tau = np.zeros(self.model.n), np.zeros(3)
            if (
                take_requests > self.estop_take_mark and current is not None and not current.estop
                and feedback_age <= self.config.feedback_timeout
            ):
                with self.lock:
                    self.policy.clear_estop()
                self.state = self.controller.initial_state(self.q, self.state.theta_hat)
                self.master.reset_arming()
                self.master.request_arming()
                self.mode = Mode.ARMING
                self.emit(now, "estop_cleared", "estop_cleared", "info", "estop cleared by the operator (take): re-arming")

    def control(self, now: float, operator) -> None:
        dt = self.period if self.last_step_at is None else min(max(now - self.last_step_at, 0.0), 4 * self.period)
        self.last_step_at = now
        try:
            self.state, out = self.controller.step(self.state, self.q, None if self.output_feedback else self.v, operator, dt)
            u_s = out.u_s.tolist() if isinstance(out.u_s, np.ndarray) else out.u_s
            tau = self.kinematics.wheel_torques(self.q, u_s)
            if not all(math.isfinite(t) for t in tau):
                raise NonFiniteCommand("non-finite wheel torque")
        except NonFiniteCommand as exc:
            self.tau, self.u_s = np.zeros(3), np.zeros(self.model.n)
            self.master.send_torques(self.tau)
            self.estop(now, f"non-finite command: {exc}")
            return
        peak = max(abs(t) for t in tau)
        if peak > self.config.torque_limit:
            scale = self.config.torque_limit / peak
            tau = tuple(t * scale for t in tau)
            self.saturated += 1
        self.out, self.u_s, self.tau = out, out.u_s, np.array(tau)
        self.torque_ready.add(time.monotonic() - now)
        if self.config.torque_at > 0.0:
            poll_until((now if self.deadline is None else self.deadline) + self.config.torque_at)
        self.master.send_torques(tau)
        sent = time.monotonic()
        self.torque_out.add(sent - now)
        self.sensor_to_torque.add(sent - now + self.feedback_age)
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

    def estop(self, now: float, reason: str) -> None:
        self.master.estop_all()
        self.tau, self.u_s = np.zeros(3), np.zeros(self.model.n)
        self.mode = Mode.ESTOPPED
        self.estops += 1
        with self.lock:
            self.estop_take_mark = self.policy.take_requests
        self.emit(now, f"estop:{reason[:12]}", "estop", "critical", f"ESTOP: {reason}")

    # -------------------------------------------------------------- telemetry
    def telemetry(self, now: float) -> None:
        """Once a period, after the send: RobotState at `telemetry_rate` on the clock, not every so many
        ticks, so a loop that misses deadlines still reports at its rate. When one is due its three
        stages (`telemetry_stage`) run in this period and the next two; at a telemetry rate above a
        third of the loop's, each goes out whole in the period it is due."""
        if self._state_stage is None:
            if not self.state_schedule.due(now):
                return
            if TELEMETRY_STAGES * self.period > self.state_schedule.period:
                self.publish_state(now)
                return
            self._state_stage = 0
        stage = self._state_stage
        self._state_stage = stage + 1 if stage + 1 < TELEMETRY_STAGES else None
        self.telemetry_stage(stage, now)

    def heartbeats(self, now: float) -> None:
        """A Heartbeat message once a second on the clock (the first one before the loop's clock starts)."""
        if self.heartbeat_schedule.due(now):
            self.publish_heartbeat()

    def publish_state(self, now: float) -> None:
        """One RobotState of this period, captured, built, encoded and put at once."""
        for stage in range(TELEMETRY_STAGES):
            self.telemetry_stage(stage, now)

    def telemetry_stage(self, stage: int, now: float) -> None:
        """One of a RobotState's three stages, each in its own period (`telemetry`): 0 captures this period's
        values and works out the reference q_r (on demand, `StepOutput.q_r`), 1 builds the message, 2
        encodes and puts it. At once they took 0.5–0.65 ms of the loop thread in one period, against
        ≈ 0.6 ms for a whole ordinary period; spread, no period carries much more than another. The
        message is the capture's (its seq and time): the values are never mutated after their period
        (each tick makes new arrays), so building it later changes nothing but the CPU's timing."""
        try:
            if stage == 0:
                self._state_message = None
                self._state_capture = self._capture_state(now)
            elif stage == 1 and self._state_capture is not None:
                capture, self._state_capture = self._state_capture, None
                self._state_message = robot_state(*capture)
            elif stage == 2 and self._state_message is not None:
                message, self._state_message = self._state_message, None
                self.state_pub.put(encode_message(message, self.dims))
        except Exception as exc:  # noqa: BLE001 — telemetry must not stop the loop
            self._state_capture = self._state_message = None
            self.emit(now, "telemetry", "info", "warning", f"RobotState not sent: {type(exc).__name__}: {exc}")

    def _capture_state(self, now: float) -> tuple:
        """`telemetry.robot_state`'s arguments for this period."""
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
        return (self.state_seq, time.time(), self.q, v_used, out, self.loop.feasible, self.loop.sharing.bands,
                self.tau, self.u_s, self.mode is Mode.ESTOPPED, self.lease_holder, link,
                out.theta_estimate if out is not None else self.state.theta_hat)

    def publish_heartbeat(self) -> None:
        self.heartbeat_seq += 1
        try:
            self.alive_pub.put(encode_message(Heartbeat(ROLE, self.config.robot_id, self.heartbeat_seq, time.time())))
        except Exception:  # noqa: BLE001
            pass

    # --------------------------------------------------------------- shutdown
    def shutdown(self) -> None:
        """Zero torque, then IDLE to every axis (twice: a lost frame must not leave an axis armed)."""
        self.tau, self.u_s = np.zeros(3), np.zeros(self.model.n)
        for _ in range(2):
            self.master.send_torques(self.tau)
            self.master.idle_all()
        self.emit(time.monotonic(), "shutdown", "info", "info", "controller stopping: zero torque, axes IDLE")
