"""What `sharedctl demo` measures: ground truth and telemetry recorded from Zenoh, the metrics
computed from them, and the in-process sampled references the distributed run is compared with.

The run's clock: t = 0 is the instant the operator was granted the lease, as the controller
reports it (`RobotState.lease_since`, on the controller's wall clock — this host's), carried to
this process's monotonic clock; a controller that does not report it (wire 1.1) leaves the
arrival of the first RobotState naming a holder. On that clock: a RobotState at its own `time`,
an Event at its own `time` (`at` in the event log), a GroundTruth sample at the robot's
simulation time mapped by the smallest arrival − simulation-time offset seen (the loopback
transit, well under a millisecond)."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import numpy as np

from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.messages import Authority, Event, GroundTruth, RobotState
from sharedctl.protocol.msgpack_codec import decode_message
from sharedctl.protocol.wire_types import ROBOT_DIMS

# run vs `reference_plant` (the same plant in process); chosen from measurements, see docs/console.md
TOLERANCE = {"final_pose_distance": 0.05, "human_authority_difference": 0.1}


@dataclass
class Recorder:
    """GroundTruth, RobotState and Events as they arrive (Zenoh callback threads)."""

    feasible: object
    lock: threading.Lock = field(default_factory=threading.Lock)
    truth: list = field(default_factory=list)        # (arrival, q, qd, inside, margin, simulation time)
    states: list = field(default_factory=list)       # (arrival, RobotState)
    events: list = field(default_factory=list)
    rejected: int = 0
    operator_start: float | None = None              # the run's t = 0 (monotonic): the lease instant
    lease_wall: float | None = None                  # the same instant on the controller's (wall) clock
    run_clock: str | None = None                     # "lease" (reported by the controller) or "first_state"
    truth_offset: float = float("inf")               # min over samples of arrival − simulation time
    in_control: threading.Event = field(default_factory=threading.Event)

    def on_truth(self, sample) -> None:
        msg = self._decode(sample, GroundTruth)
        if msg is not None:
            now = time.monotonic()
            q = np.asarray(msg.q, float)
            row = (now, q, np.asarray(msg.qd, float), self.feasible.contains(q), self.feasible.margin(q), msg.time)
            with self.lock:
                self.truth.append(row)
                self.truth_offset = min(self.truth_offset, now - msg.time)

    def on_state(self, sample) -> None:
        msg = self._decode(sample, RobotState)
        if msg is not None:
            now = time.monotonic()
            with self.lock:
                self.states.append((now, msg))
                if self.operator_start is None and msg.lease_holder is not None:
                    if msg.lease_since is not None:
                        self.lease_wall = msg.lease_since
                        self.operator_start = msg.lease_since - (time.time() - time.monotonic())
                        self.run_clock = "lease"
                    else:
                        self.operator_start, self.run_clock = now, "first_state"
                    self.in_control.set()

    def controller_time(self, wall: float, arrival: float) -> float:
        """A controller message's own `time` (wall clock) on the run's clock; its arrival if t = 0 has no
        wall-clock instant."""
        if self.lease_wall is not None:
            return wall - self.lease_wall
        return arrival - (self.operator_start or 0.0)

    def on_event(self, sample) -> None:
        msg = self._decode(sample, Event)
        if msg is not None:
            with self.lock:
                self.events.append((time.monotonic(), msg))

    def wait_at_rest(self, speed: float, timeout: float, hold: float = 0.2) -> float:
        """Seconds until the ground-truth speed |(ẋ, ẏ)| stays below `speed` for `hold` s (or `timeout`)."""
        start = time.monotonic()
        calm_since = None
        while time.monotonic() - start < timeout:
            with self.lock:
                last = self.truth[-1] if self.truth else None
            if last is not None and np.linalg.norm(last[2][:2]) < speed:
                calm_since = calm_since or time.monotonic()
                if time.monotonic() - calm_since >= hold:
                    break
            else:
                calm_since = None
            time.sleep(0.02)
        return time.monotonic() - start

    def _decode(self, sample, kind):
        try:
            return decode_message(sample.payload.to_bytes(), ROBOT_DIMS, expect=kind)
        except ProtocolError:
            with self.lock:
                self.rejected += 1
            return None


def measure(rec: Recorder, start: float | None, duration: float) -> dict:
    """The run's summary: safety on the ground truth (whole run), tracking/authority on telemetry (the window)."""
    with rec.lock:
        truth, states, events = list(rec.truth), list(rec.states), list(rec.events)
    end = None if start is None else start + duration
    inside = [t for t in truth if start is not None and start <= t[0] <= end]
    last = inside[-1] if inside else (truth[-1] if truth else None)
    window = [s for a, s in states if start is not None and start <= a <= end]
    err = np.array([np.linalg.norm(np.subtract(s.q, s.q_ref)) for s in window])
    human = np.array([s.authority is Authority.HUMAN for s in window])
    kinds: dict[str, int] = {}
    for _, ev in events:
        kinds[ev.kind.value] = kinds.get(ev.kind.value, 0) + 1
    origin = start if start is not None else (events[0][0] if events else 0.0)
    log = [{"t": round(a - origin, 3), "at": round(rec.controller_time(ev.time, a), 4) if start is not None else None,
            "kind": ev.kind.value, "severity": ev.severity.value, "source": ev.source,
            "text": ev.text} for a, ev in events[:100]]
    times = [a for a, s in states if start is not None and start <= a <= end]
    origin_t = start if start is not None else (truth[0][0] if truth else 0.0)
    outside = [t[0] - origin_t for t in truth if not t[3]]
    worst = min(truth, key=lambda t: t[4]) if truth else None
    return {
        "violations": len(outside),
        "violations_after_window": sum(1 for t in outside if end is not None and t > duration),
        "first_violation_t": round(outside[0], 3) if outside else None,
        "min_margin": float(worst[4]) if worst else float("nan"),
        "min_margin_t": round(worst[0] - origin_t, 3) if worst else None,
        "final_speed": float(np.linalg.norm(last[2])) if last is not None else float("nan"),
        "final_pose": [float(x) for x in last[1]] if last is not None else [],
        "truth_samples": len(truth),
        "tracking_rmse": float(np.sqrt(np.mean(err**2))) if err.size else float("nan"),
        "final_error": float(err[-1]) if err.size else float("nan"),
        "human_authority": float(np.mean(human)) if human.size else 0.0,
        "switches": int(np.count_nonzero(human[1:] != human[:-1])) if human.size else 0,
        "theta_hat": [float(x) for x in window[-1].theta_hat] if window else [],
        "finite": bool(window) and all(np.all(np.isfinite(s.q)) for s in window),
        "steps": len(window),
        "duration": float(times[-1] - start) if times else 0.0,
        "estops": kinds.get("estop", 0),
        "events": kinds,
        "event_log": log,
        "rejected_messages": rec.rejected,
        "run_clock": rec.run_clock,
    }


TRUTH_SPAN = 0.1      # s of ground truth kept either side of an instant (`states_at`)
TORQUE_SPAN = 0.06    # s of reported wheel torques kept before it (three telemetry periods at 50 Hz)


def states_at(rec: Recorder, instants: list[tuple[str, float]]) -> list[dict]:
    """The ground truth and the controller's reported wheel torques around each (label, t) — t on the run's
    clock, e.g. the instant a fault fired — for a forecast from the true state at that instant
    (services/studies/campaign/stopping.py): `truth` rows [t, *q, *q̇] within ±TRUTH_SPAN, `torques` rows
    [t, *τ] within TORQUE_SPAN before it, both on the run's clock."""
    with rec.lock:
        truth, states = list(rec.truth), list(rec.states)
    if rec.operator_start is None:
        return []
    start, offset = rec.operator_start, rec.truth_offset
    sim = [((row[5] + offset if len(row) > 5 and np.isfinite(offset) else row[0]) - start, row) for row in truth]
    torques = [(rec.controller_time(msg.time, a), msg) for a, msg in states]
    out = []
    for label, t in instants:
        out.append({
            "what": label, "t": t,
            "truth": [[round(ts, 5), *map(float, row[1]), *map(float, row[2])] for ts, row in sim
                      if abs(ts - t) <= TRUTH_SPAN],
            "torques": [[round(ts, 5), *map(float, msg.wheel_torques)] for ts, msg in torques
                        if t - TORQUE_SPAN <= ts <= t],
        })
    return out


def reference_run(scenario, controller: str | None, duration: float) -> dict:
    """`simulate_sampled` of the same scenario and law at 500 Hz: the in-process reference (the model as plant)."""
    from sharedctl.metrics import summarize
    from sharedctl.sampled import simulate_sampled

    loop, q0, v0 = scenario.closed_loop(controller)
    period = 0.002
    trace = simulate_sampled(loop, q0, v0, duration, period)
    summary = summarize(trace, period)
    summary["final_pose"] = [float(x) for x in trace.q[-1]]
    summary["final_speed"] = float(np.linalg.norm(trace.v[-1]))
    return summary


def plant_reference_run(scenario, controller: str | None, duration: float) -> dict:
    """The same sampled loop (SharedController.step at 500 Hz, the scripted operator with the wire's [−1, 1]
    clip) on the simulated robot's true plant — `sharedctl robot`'s wheel friction and drive limits
    (services/robot/plant.py, RK4 at 1 kHz). What the distributed run must reproduce up to its latencies,
    rates and odometry; `reference` differs from both by the friction the model does not have."""
    from sharedctl.human import intent
    from sharedctl.shared_controller import OperatorInput, SharedController
    from sharedctl.sharing import Authority as CoreAuthority

    from sharedctl.services.robot.plant import Plant, RobotSimConfig

    loop, q0, v0 = scenario.closed_loop(controller)
    model, human, feasible = loop.model, loop.human, loop.feasible
    ctrl = SharedController(model, feasible, loop.controller, loop.sharing, loop.reference, loop.backup)
    state = ctrl.initial_state(q0, loop.theta_hat0)
    plant = Plant(model, RobotSimConfig.from_table(scenario.data.get("robot_sim")))
    ps = plant.initial_state(q0, v0)
    period, substeps = 0.002, 2
    steps = int(round(duration / period))
    human_share, errors, margins, outside, out = [], [], [], 0, None
    for k in range(steps):
        t = k * period
        d = np.clip(human.command(t, ps.q, ps.qd).deflection, -1.0, 1.0)
        operator = OperatorInput(human.desired(t), human.kp * d, intent(human.kp, d))
        state, out = ctrl.step(state, ps.q, None if loop.controller.observer else ps.qd, operator, period)
        human_share.append(out.authority is CoreAuthority.HUMAN)
        errors.append(float(np.linalg.norm(ps.q - out.q_r)))
        margins.append(feasible.margin(ps.q))
        outside += not feasible.contains(ps.q)
        tau = model.wheel_torques(ps.q, out.u_s)
        for _ in range(substeps):
            ps = plant.step(ps, tau, period / substeps)
    human_share, err = np.array(human_share), np.array(errors)
    err = err[np.isfinite(err)]
    return {
        "violations": int(outside), "min_margin": float(min(margins)),
        "tracking_rmse": float(np.sqrt(np.mean(err**2))) if err.size else float("nan"),
        "final_error": float(err[-1]) if err.size else float("nan"),
        "human_authority": float(np.mean(human_share)),
        "switches": int(np.count_nonzero(human_share[1:] != human_share[:-1])),
        "theta_hat": [float(x) for x in out.theta_estimate] if out is not None else [],
        "final_pose": [float(x) for x in ps.q], "final_speed": float(np.linalg.norm(ps.qd)),
        "steps": steps, "duration": steps * period,
    }


def deviation(run: dict, ref: dict) -> dict:
    if not run["final_pose"] or not ref.get("final_pose"):
        return {}
    a, b = np.asarray(run["final_pose"]), np.asarray(ref["final_pose"])
    dev = {
        "final_pose_distance": float(np.linalg.norm(a[:2] - b[:2])),
        "final_yaw_difference": float(abs(a[2] - b[2])) if a.size > 2 else 0.0,
        "human_authority_difference": float(abs(run["human_authority"] - ref["human_authority"])),
        "tracking_rmse_difference": float(abs(run["tracking_rmse"] - ref["tracking_rmse"])),
        "min_margin_difference": float(abs(run["min_margin"] - ref["min_margin"])),
        "theta_hat_difference": float(np.linalg.norm(np.subtract(run["theta_hat"], ref["theta_hat"])))
        if len(run["theta_hat"]) == len(ref["theta_hat"]) else None,
    }
    dev["within_tolerance"] = all(dev[k] <= v for k, v in TOLERANCE.items())
    return dev
