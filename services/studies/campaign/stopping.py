"""Stopping distance of the simulated robot when the drives stop driving, and what it predicts for a fault.

When the controller dies, hangs or loses the bus, every axis keeps its last torque setpoint until
its watchdog expires (T_w = 0.1 s) and then goes IDLE: no torque, and its wheel's fail-safe brake
engages (a Coulomb torque c_b per wheel, services/robot/plant.py; c_b = 0 for a robot without
brakes, which only the wheels' friction slows). An estop disarms at once (T_w = 0). For a translation at speed v along
a unit direction e (yaw ψ = 0), the wheel speeds are ω_j = (b_j·e) v with b_j the j-th column of
B(ψ)'s translational rows, and the friction decelerates the body by

    a(v) = a_c + k v,   a_c = (c + c_b) Σ_j |b_j·e| / m1,   k = b Σ_j (b_j·e)² / m1 = 3b / (2 r² m1)

(c: Coulomb torque, c_b: brake torque, b: viscous coefficient per wheel, m1 the model's translational inertia;
Σ_j (b_j·e)² = 3/(2r²) for every direction, Σ_j |b_j·e| lies between √3/r and 2/r, least along
y). Integrating v dv/dx = −(a_c + k v) from v to 0 gives the coasting distance

    s(v) = v/k − (a_c/k²) ln(1 + k v / a_c),

and with the held torque's acceleration a_h over T_w the stopping distance

    D(v) = v T_w + ½ a_h T_w² + s(v + a_h T_w).

A loss of actuation at speed v toward a face at distance d keeps the robot inside only if
D(v) < d. `speed_limit(d)` inverts D. `forecast` measures the same thing on the robot's true
plant (RK4, the same friction as `sharedctl robot`): it runs the scenario's sampled loop
(`SharedController.step` at 500 Hz) to the fault time, holds the last torque for T_w and lets
the robot coast to rest, and reports the smallest margin reached.

`forecast_at` is the judge of a distributed run: the same coast on the plant, started from the
run's own ground truth at the instant the fault actually fired (`state_at`: the two ground-truth
samples around it, interpolated). What is not known exactly — the torque the drives hold (the
controller's last reported one, or the one the ground truth's acceleration shows just before the
fault), how long they hold it (the watchdog counts from the last frame that reached them, up to a
period before the fault) — is taken in the robot's favour: the outcome is the best over the
candidates, so a violation it shows is one that must happen. Pure: no clocks, no I/O.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sharedctl.human import intent
from sharedctl.shared_controller import OperatorInput, SharedController

from sharedctl.services.robot.plant import Plant, RobotSimConfig

WATCHDOG = 0.1          # s, the drives' default watchdog (RobotSimConfig.watchdog_timeout)
CONTROL_PERIOD = 0.002  # s, the controller daemon's period


@dataclass(frozen=True)
class CoastModel:
    """Friction deceleration a(v) = a_c + k v of the unpowered robot along one direction."""

    coulomb: float   # a_c, m/s²
    viscous: float   # k, 1/s

    def deceleration(self, v: float) -> float:
        return self.coulomb + self.viscous * v

    def coast_distance(self, v: float) -> float:
        """s(v): distance (m) from speed v (m/s) to rest with no drive torque."""
        if v <= 0:
            return 0.0
        a, k = self.coulomb, self.viscous
        if k <= 0:
            return v * v / (2.0 * a) if a > 0 else math.inf
        if a <= 0:
            return v / k
        return v / k - (a / (k * k)) * math.log1p(k * v / a)

    def stopping_distance(self, v: float, hold: float = WATCHDOG, hold_accel: float = 0.0) -> float:
        """D(v) = v T_w + ½ a_h T_w² + s(v + a_h T_w): the held torque for `hold` s, then coasting."""
        v_end = max(v + hold_accel * hold, 0.0)
        return max(v * hold + 0.5 * hold_accel * hold * hold, 0.0) + self.coast_distance(v_end)

    def speed_limit(self, distance: float, hold: float = WATCHDOG, hold_accel: float = 0.0) -> float:
        """The largest speed (m/s) toward a face `distance` m away that still stops short of it."""
        if distance <= 0 or self.stopping_distance(0.0, hold, hold_accel) >= distance:
            return 0.0
        lo, hi = 0.0, 1.0
        while self.stopping_distance(hi, hold, hold_accel) < distance and hi < 1e3:
            hi *= 2.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.stopping_distance(mid, hold, hold_accel) < distance else (lo, mid)
        return lo


def coast_model(plant: Plant, direction=(0.0, 1.0), psi: float = 0.0, braked: bool = True) -> CoastModel:
    """a_c and k of `plant` for a translation along `direction` (x, y) at yaw `psi`, with the
    drives disarmed (their brakes engaged, if the plant has any; `braked=False`: friction only)."""
    e = np.asarray(direction, float)
    e = e / np.linalg.norm(e)
    B = plant.model.input_matrix(np.array([0.0, 0.0, psi]))
    proj = B[:2, :].T @ e                       # b_j·e, rad/m per wheel
    m1 = float(plant.model.theta[0])
    c = plant.config.friction_coulomb + (plant.config.brake_torque if braked else 0.0)
    b = plant.config.friction_viscous
    return CoastModel(coulomb=c * float(np.sum(np.abs(proj))) / m1, viscous=b * float(np.sum(proj * proj)) / m1)


def worst_coast_model(plant: Plant, braked: bool = True) -> CoastModel:
    """The least deceleration over all directions (Σ|b_j·e| = √3/r, along ±y at ψ = 0)."""
    samples = [coast_model(plant, (math.cos(a), math.sin(a)), braked=braked) for a in np.linspace(0.0, math.pi, 181)]
    return min(samples, key=lambda m: m.coulomb)


# ----- measured on the true plant ---------------------------------------------------------
@dataclass(frozen=True)
class LoopSample:
    t: float
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray      # wheel torques commanded for the period starting at t


@dataclass(frozen=True)
class CoastOutcome:
    """A loss of actuation at t_fault, measured on the plant."""

    t_fault: float
    speed: float             # |(ẋ, ẏ)| at the fault, m/s
    approach_speed: float    # speed toward the nearest translational face, m/s (≤ 0: moving away)
    margin: float            # feasible-set margin at the fault, m
    min_margin: float        # smallest margin from the fault until at rest
    travelled: float         # path length from the fault to rest, m
    predicted_distance: float  # D(speed) of the worst-direction coast model
    rest_time: float         # s from the fault to rest
    hold: float = WATCHDOG   # s the torque was held before the brakes (the best candidate's)
    candidates: int = 1      # (held torque, hold) pairs tried; the outcome is the best of them

    @property
    def violates(self) -> bool:
        return self.min_margin <= 0.0


def _start(scenario, controller):
    """The scenario's closed loop, its shared controller and initial state, the true plant and its state."""
    loop, q0, v0 = scenario.closed_loop(controller)
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference, loop.backup)
    plant = Plant(loop.model, RobotSimConfig.from_table(scenario.data.get("robot_sim")))
    return loop, ctrl, ctrl.initial_state(q0, loop.theta_hat0), plant, plant.initial_state(q0, v0)


def sampled_loop(scenario, duration: float, controller: str | None = None, period: float = CONTROL_PERIOD):
    """The scenario's sampled shared loop on the true plant (as `sharedctl robot` integrates it):
    a list of `LoopSample`s, one per control period, and the plant."""
    loop, ctrl, state, plant, ps = _start(scenario, controller)
    model, human = loop.model, loop.human
    samples = []
    for k in range(int(round(duration / period))):
        t = k * period
        d = np.clip(human.command(t, ps.q, ps.qd).deflection, -1.0, 1.0)
        operator = OperatorInput(human.desired(t), human.kp * d, intent(human.kp, d))
        state, out = ctrl.step(state, ps.q, None if loop.controller.observer else ps.qd, operator, period)
        tau = np.asarray(model.wheel_torques(ps.q, out.u_s), float)
        samples.append(LoopSample(t, ps.q.copy(), ps.qd.copy(), tau))
        for _ in range(2):
            ps = plant.step(ps, tau, period / 2)
    return samples, plant, loop.feasible


def coast(plant: Plant, feasible, q, qd, tau_hold, hold: float = WATCHDOG, dt: float = 1e-3,
          rest_speed: float = 1e-3, max_time: float = 30.0):
    """Hold `tau_hold` for `hold` s, then disarmed (zero torque, brakes engaged) until at rest:
    (min margin, path length, time)."""
    ps = plant.initial_state(q, qd)
    zero = (0.0, 0.0, 0.0)
    off, braked = zero, plant.brake_torques((True, True, True))
    min_margin, path, t = feasible.margin(ps.q), 0.0, 0.0
    while t < max_time:
        tau, brakes = (tau_hold, off) if t < hold else (zero, braked)
        nxt = plant.step(ps, tau, dt, brakes)
        path += float(np.linalg.norm(nxt.q[:2] - ps.q[:2]))
        ps, t = nxt, t + dt
        min_margin = min(min_margin, feasible.margin(ps.q))
        if t >= hold and float(np.linalg.norm(ps.qd[:2])) < rest_speed and abs(float(ps.qd[2])) < rest_speed:
            break
    return min_margin, path, t


def approach_speed(feasible, q, qd) -> float:
    """Rate at which the nearest face of the best region is approached (m/s; rows with unit (x, y) normals)."""
    region = max(feasible.regions, key=lambda r: r.margin(q))
    values = region.values(q)
    rows = [j for j in range(len(values)) if np.linalg.norm(region.K[j, :2]) > 0.5]
    j = max(rows, key=lambda i: values[i])
    return float(region.K[j] @ qd) / float(np.linalg.norm(region.K[j, :2]))


def forecast(samples, plant: Plant, feasible, t_fault: float, hold: float = WATCHDOG) -> CoastOutcome:
    """Loss of actuation at `t_fault` (s after the operator's start): last torque held `hold` s, then coasting."""
    k = min(max(int(round(t_fault / (samples[1].t - samples[0].t))), 0), len(samples) - 1)
    s = samples[k]
    tau_hold = samples[k - 1].tau if k > 0 else np.zeros(3)
    min_margin, path, rest = coast(plant, feasible, s.q, s.qd, tuple(float(x) for x in tau_hold), hold)
    speed = float(np.linalg.norm(s.qd[:2]))
    return CoastOutcome(t_fault=s.t, speed=speed, approach_speed=approach_speed(feasible, s.q, s.qd),
                        margin=feasible.margin(s.q), min_margin=min_margin, travelled=path,
                        predicted_distance=worst_coast_model(plant).stopping_distance(speed, hold), rest_time=rest)


def delayed_loop_margin(scenario, duration: float, loop_delay: float, controller: str | None = None,
                        period: float = CONTROL_PERIOD, hang: tuple[float, float] | None = None,
                        predictive: bool = True) -> tuple[float, float]:
    """(min margin, peak speed) of the scenario's sampled loop on the true plant when the torque loop is
    delayed by `loop_delay` s in all (CAN feedback age + command transit, rounded to whole periods): the
    controller computes from the state `loop_delay` old, as a CAN delay of loop_delay/2 each way does.
    `hang` = (START, DURATION): the controller does not run in that window (SIGSTOP shorter than the
    drives' watchdog) and the drives hold its last torque; it then resumes on fresh feedback.
    `predictive`: the controller is told the feedback's age (as the daemon measures it) and runs on
    the predicted state (SharedController.step's `delay`); False: it runs on the old state as is."""
    loop, ctrl, state, plant, ps = _start(scenario, controller)
    model, human = loop.model, loop.human
    lag = int(round(loop_delay / period))
    history = [(ps.q.copy(), ps.qd.copy())] * (lag + 1)
    min_margin, peak = loop.feasible.margin(ps.q), 0.0
    for k in range(int(round(duration / period))):
        t = k * period
        q, qd = history[0]
        hung = hang is not None and hang[0] <= t < hang[0] + hang[1]
        if not hung or k == 0:
            d = np.clip(human.command(t, q, qd).deflection, -1.0, 1.0)
            operator = OperatorInput(human.desired(t), human.kp * d, intent(human.kp, d))
            state, out = ctrl.step(state, q, None if loop.controller.observer else qd, operator, period,
                                   lag * period if predictive else 0.0)
            tau = np.asarray(model.wheel_torques(q, out.u_s), float)
        for _ in range(2):
            ps = plant.step(ps, tau, period / 2)
            min_margin = min(min_margin, loop.feasible.margin(ps.q))
        peak = max(peak, float(np.linalg.norm(ps.qd[:2])))
        history = history[1:] + [(ps.q.copy(), ps.qd.copy())]
    return min_margin, peak


def approach_window(samples, plant: Plant, feasible, rest_speed: float = 0.02) -> tuple[float, float, float, float]:
    """(start, end, peak speed, reach) of a sampled loop's approach to a face: the peak approach speed, the
    stopping distance D from it (the last torque 0 held T_w, then the brakes), the first instant the
    nearest face is within D (a loss of actuation from then on can end at it), and the first instant after
    that at which the robot is at rest."""
    speeds = [approach_speed(feasible, s.q, s.qd) for s in samples]
    peak = max(speeds)
    reach = worst_coast_model(plant).stopping_distance(peak)
    start = next(s.t for s in samples if feasible.margin(s.q) <= reach)
    end = next(s.t for s in samples if s.t > start and float(np.linalg.norm(s.qd[:2])) < rest_speed)
    return start, end, peak, reach


# ----- from the ground truth at the instant a fault fired --------------------------------------
def state_at(truth, t: float) -> tuple[float, np.ndarray, np.ndarray] | None:
    """(t, q, q̇) at `t` from ground-truth rows [t_i, *q, *q̇] sorted by t_i: linear between the samples
    either side of `t`; the last sample before `t` if none follows it; None if none precedes it."""
    rows = [np.asarray(r, float) for r in truth]
    before = [r for r in rows if r[0] <= t]
    if not before:
        return None
    a = before[-1]
    after = [r for r in rows if r[0] > t]
    n = (len(a) - 1) // 2
    if not after or after[0][0] <= a[0]:
        return t, a[1:1 + n].copy(), a[1 + n:].copy()
    b = after[0]
    w = (t - a[0]) / (b[0] - a[0])
    x = (1.0 - w) * a[1:] + w * b[1:]
    return t, x[:n], x[n:]


def true_plant(scenario, controller: str | None = None):
    """(the robot's true plant as `sharedctl robot` integrates it, the scenario's admissible set)."""
    loop, _, _ = scenario.closed_loop(controller)
    return Plant(loop.model, RobotSimConfig.from_table(scenario.data.get("robot_sim"))), loop.feasible


def held_torques(torques, t: float, count: int = 1) -> list[tuple[float, ...]]:
    """The last `count` wheel torques reported at or before `t` (rows [t_i, *τ]); zero torque if none."""
    rows = sorted((r for r in torques if r[0] <= t), key=lambda r: r[0])[-count:]
    return [tuple(float(x) for x in r[1:]) for r in rows] or [(0.0, 0.0, 0.0)]


def torque_from_truth(plant: Plant, truth, t: float) -> tuple[float, ...] | None:
    """The wheel torques the drives applied over the last ground-truth interval ending at or before `t`, read
    from the acceleration it shows: u = M q̈ less the model's coupling (the plant's own equations), τ =
    B(ψ)⁻¹ u plus the wheels' friction. None without two samples before `t`."""
    rows = [np.asarray(r, float) for r in truth if r[0] <= t]
    if len(rows) < 2 or rows[-1][0] <= rows[-2][0]:
        return None
    a, b = rows[-2], rows[-1]
    n = (len(a) - 1) // 2
    qdd = (b[1 + n:] - a[1 + n:]) / (b[0] - a[0])
    q, qd = 0.5 * (a[1:1 + n] + b[1:1 + n]), 0.5 * (a[1 + n:] + b[1 + n:])
    m1, m3, coupling = (float(x) for x in plant.model.theta)
    u = np.array([m1 * qdd[0] + coupling * qd[2] * qd[1], m1 * qdd[1] - coupling * qd[2] * qd[0], m3 * qdd[2]])
    omega = plant.wheel_speeds(plant.initial_state(q, qd))
    tau = np.asarray(plant.model.wheel_torques(q, u), float) + plant.friction(omega)
    return tuple(float(x) for x in tau)


def forecast_at(plant: Plant, feasible, truth, torques, t_fired: float,
                holds: tuple[float, ...] = (WATCHDOG,)) -> CoastOutcome | None:
    """A loss of actuation at `t_fired` (the run's clock), from the run's ground truth at that instant:
    each held torque — the last one the controller reported (`held_torques`, up to a telemetry period
    old) and the one the ground truth's acceleration shows just before (`torque_from_truth`, over the
    last ground-truth interval) — for each of `holds` s, then the
    brakes; the best outcome (largest min margin) of them. None without a ground-truth sample at or
    before `t_fired`."""
    at = state_at(truth, t_fired)
    if at is None:
        return None
    _, q, qd = at
    best = None
    held = held_torques(torques, t_fired) if torques else []
    shown = torque_from_truth(plant, truth, t_fired)
    held += [shown] if shown is not None else []
    candidates = [(tau, hold) for tau in held or [(0.0, 0.0, 0.0)] for hold in holds]
    for tau, hold in candidates:
        min_margin, path, rest = coast(plant, feasible, q, qd, tau, hold)
        if best is None or min_margin > best[0]:
            best = (min_margin, path, rest, hold)
    speed = float(np.linalg.norm(qd[:2]))
    return CoastOutcome(t_fault=t_fired, speed=speed, approach_speed=approach_speed(feasible, q, qd),
                        margin=feasible.margin(q), min_margin=best[0], travelled=best[1],
                        predicted_distance=worst_coast_model(plant).stopping_distance(speed, best[3]),
                        rest_time=best[2], hold=best[3], candidates=len(candidates))
