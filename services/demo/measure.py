"""What `sharedctl demo` measures: ground truth and telemetry recorded from Zenoh, the metrics
computed from them, and the in-process sampled references the distributed run is compared with."""
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
    truth: list = field(default_factory=list)        # (arrival, q, qd, inside, margin)
    states: list = field(default_factory=list)       # (arrival, RobotState)
    events: list = field(default_factory=list)
    rejected: int = 0
    operator_start: float | None = None              # arrival of the first RobotState with the operator in control
    in_control: threading.Event = field(default_factory=threading.Event)

    def on_truth(self, sample) -> None:
        msg = self._decode(sample, GroundTruth)
        if msg is not None:
            q = np.asarray(msg.q, float)
            row = (time.monotonic(), q, np.asarray(msg.qd, float), self.feasible.contains(q), self.feasible.margin(q))
            with self.lock:
                self.truth.append(row)

    def on_state(self, sample) -> None:
        msg = self._decode(sample, RobotState)
        if msg is not None:
            now = time.monotonic()
            with self.lock:
                self.states.append((now, msg))
                if self.operator_start is None and msg.lease_holder is not None:
                    self.operator_start = now
                    self.in_control.set()

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
    log = [{"t": round(a - origin, 3), "kind": ev.kind.value, "severity": ev.severity.value, "source": ev.source,
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
    }


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
