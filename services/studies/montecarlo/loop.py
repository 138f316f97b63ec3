"""The distributed loop's faults for a batch of robots: the controller daemon, the CAN link, the
drives and the operator link, modelled as `sharedctl robot` and the daemon behave.

Per control period k (2 ms) and robot, in this order:

1. the operator (the console, every `operator_every` periods) deflects the handle from the
   state it sees (the controller's feedback sample), clipped to the wire's [−1, 1]; the command
   reaches the controller `operator_delay` periods later unless lost (Bernoulli `operator_loss`)
   or sent inside a blackout window; the controller holds the newest command that arrived and
   goes hands-off (u_h = 0, v_h = 0, the wish held at its last q_d with zero rates) once it is
   older than the daemon's staleness timeout (0.3 s), or before any command (wish = the pose);
2. the controller runs unless killed (for good, from `kill_at`), hung (`hang_at` for
   `hang_periods`) or stopped by its estop; if it runs and any drive has disarmed, it stops every
   drive for good (the daemon's estop on an axis reporting an error); else it steps the sampled
   shared controller (sharedctl.batched.sampled) on the plant's state `feedback` periods old, told
   the loop delay L = feedback + transit periods, and sends each wheel's torque frame, which is
   lost with probability `torque_loss` or reaches its drive `transit` periods later;
3. two physics steps (1 ms): at each, a drive not fed for more than T_w (the watchdog) disarms
   and its brake engages; frames due are applied by armed drives; then one RK4 step of the true
   plant (plant.py: the robot's own friction, drive limits, brakes, true θ).

The margin is the set's own rows, normalised, on the plant's true q after every physics step —
it shares no code with the controller, its backup model or FeasibleSet (as
tests/test_fault_envelope_properties.py's oracle). tests/test_montecarlo_loop.py holds a
batch to that scalar FaultLoop, robot by robot.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from sharedctl.batched import BatchProblem
from sharedctl.batched.operators import DesiredBatch
from sharedctl.batched.sampled import SampledBatch
from sharedctl.human import intent as intent_of
from sharedctl.services.controller.operator_input import DEFAULT_TIMEOUT
from sharedctl.services.robot.plant import RobotSimConfig

from .plant import DEFAULT_CONFIG, PlantBatch, numba

PERIOD = 0.002            # s, the daemon's control period
PHYSICS_SUBSTEPS = 2      # RK4 steps of the robot's plant per period (its 1 kHz)
NEVER = np.iinfo(np.int64).max // 4


@dataclass(frozen=True)
class LoopFaults:
    """Per-robot faults, arrays of shape (N,); instants and lengths in control periods."""

    feedback: np.ndarray            # periods the controller's sample is old (CAN delay feedback-ward)
    transit: np.ndarray             # periods a torque frame takes to its drive
    torque_loss: np.ndarray         # probability a torque frame is lost
    kill_at: np.ndarray             # the controller stops for good from this period (NEVER: not)
    hang_at: np.ndarray             # the controller skips `hang_periods` periods from this one
    hang_periods: np.ndarray
    operator_delay: np.ndarray      # periods an operator command takes to the controller
    operator_loss: np.ndarray       # probability an operator command is lost
    blackout_at: np.ndarray         # operator commands sent in [blackout_at, +blackout_periods) are lost
    blackout_periods: np.ndarray

    @staticmethod
    def none(N: int) -> "LoopFaults":
        zero, never = np.zeros(N, np.int64), np.full(N, NEVER, np.int64)
        return LoopFaults(zero, zero, np.zeros(N), never, never, zero, zero, np.zeros(N), never, zero)

    def replace(self, **changes) -> "LoopFaults":
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        N = self.feedback.shape[0]
        for name, value in changes.items():
            dtype = values[name].dtype
            values[name] = np.broadcast_to(np.asarray(value, dtype=dtype), (N,)).copy()
        return LoopFaults(**values)

    def take(self, index) -> "LoopFaults":
        return LoopFaults(**{f.name: getattr(self, f.name)[index] for f in fields(self)})


@dataclass
class LoopResult:
    """Per robot: the minimum margin (m; rad at a ψ face) on the true q and when, the estop, whether
    the machine acted, and the state at the end."""

    min_margin: np.ndarray
    min_margin_t: np.ndarray
    estopped: np.ndarray
    acted: np.ndarray
    nonfinite: np.ndarray
    final_speed: np.ndarray
    q: np.ndarray
    v: np.ndarray
    approach_speed_at_fault: np.ndarray   # m/s (rad/s) at which the robot closed on its nearest face at the fault


class Oracle:
    """Distances to the faces of the polytopes from their rows, normalised: max over polytopes of the
    min over rows of −(k q + t), > 0 inside the union. `margin` runs compiled where numba is installed
    (`compiled`: None, True, False as in PlantBatch); a NaN in q gives NaN either way."""

    def __init__(self, regions, compiled: bool | None = None):
        self.rows = []
        for K, T in regions:
            K, T = np.asarray(K, float), np.asarray(T, float)
            norms = np.linalg.norm(K, axis=1)
            self.rows.append((K / norms[:, None], (T / norms)[:, None]))
        if compiled and numba is None:
            raise ValueError("a compiled oracle needs numba (the montecarlo extra)")
        self.compiled = numba is not None if compiled is None else bool(compiled)
        self._K = np.ascontiguousarray(np.vstack([K for K, _ in self.rows]))
        self._T = np.concatenate([T[:, 0] for _, T in self.rows])
        self._starts = np.cumsum([0] + [K.shape[0] for K, _ in self.rows])

    def margin(self, q: np.ndarray) -> np.ndarray:
        if self.compiled:
            out = np.empty(q.shape[1])
            _margins(self._K, self._T, self._starts, np.ascontiguousarray(q, float), out)
            return out
        best = None
        for K, T in self.rows:
            m = np.min(-(K @ q + T), axis=0)
            best = m if best is None else np.maximum(best, m)
        return best

    def closing_speed(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The rate at which the robot closes on the nearest face of its best polytope (≥ 0)."""
        best_margin = speed = None
        for K, T in self.rows:
            slack = -(K @ q + T)
            j = np.argmin(slack, axis=0)
            m = slack[j, np.arange(q.shape[1])]
            rate = np.einsum("in,in->n", K[j].T, v)
            if best_margin is None:
                best_margin, speed = m, rate
            else:
                better = m > best_margin
                best_margin, speed = np.where(better, m, best_margin), np.where(better, rate, speed)
        return np.maximum(speed, 0.0)


class FaultyLoop:
    """N robots of one scenario, each with its own faults, true plant and seed."""

    def __init__(self, problem: BatchProblem, regions, faults: LoopFaults, true_theta: np.ndarray | None = None,
                 config: RobotSimConfig = DEFAULT_CONFIG, brake_torque=None, seed: int | np.random.Generator = 0,
                 operator_every: int = 1, output_feedback: bool = False):
        N = problem.size
        self.N, self.faults, self.config = N, faults, config
        self.controller = SampledBatch(problem, PERIOD)
        self.output_feedback = output_feedback
        self.model = problem.model
        self.plant = PlantBatch(problem.model, problem.theta if true_theta is None else true_theta, config,
                                brake_torque)
        self.oracle = Oracle(regions)
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.ops = problem.operators
        self.operator_every = max(1, int(operator_every))
        self.q, self.v = problem.q0.copy(), problem.v0.copy()
        depth = int(faults.feedback.max()) + 1
        self.history = np.repeat(np.vstack([self.q, self.v])[None], depth, axis=0)   # (depth, 2n, N), a ring
        self.columns = np.arange(N)
        self.wish = None                                            # the last wish handed to the controller
        slots = int(faults.transit.max()) + 1
        self.pending = np.zeros((slots, 3, N))
        self.pending_mask = np.zeros((slots, 3, N), bool)
        op_slots = int(faults.operator_delay.max()) + 1
        self.op_deflection = np.zeros((op_slots, self.model.n, N))
        self.op_sent = np.zeros((op_slots, N), bool)
        self.op_time = np.zeros((op_slots, N))
        self.cmd_t = np.zeros(N)                                    # the held command's send time
        self.cmd_deflection = np.zeros((self.model.n, N))
        self.cmd_at = np.full(N, -NEVER, np.int64)                  # period it arrived (none yet)
        self.has_cmd = np.zeros(N, bool)
        self.torque = np.zeros((3, N))
        self.fed_ms = np.zeros((3, N))
        self.armed = np.ones((3, N), bool)
        self.estopped = np.zeros(N, bool)
        self.acted = np.zeros(N, bool)
        self.nonfinite = np.zeros(N, bool)
        self.k = 0
        m = self.oracle.margin(self.q)
        self.min_margin, self.min_margin_t = m, np.zeros(N)
        self.approach_at_fault = np.full(N, np.nan)
        self.watchdog_ms = config.watchdog_timeout * 1000.0
        self.period_ms = PERIOD * 1000.0
        self.physics_ms = self.period_ms / PHYSICS_SUBSTEPS
        self.stale_periods = DEFAULT_TIMEOUT / PERIOD

    # ------------------------------------------------------------------------------
    def sample(self, age: np.ndarray):
        """(q, v) of the plant `age` (N,) periods ago, at the periods' starts."""
        depth, n = self.history.shape[0], self.model.n
        if depth == 1:
            return self.q, self.v
        x = self.history[(self.k - age) % depth, :, self.columns].T
        return x[:n], x[n:]

    def operator(self, q_seen, v_seen):
        """The console's command of this period (sent or not) and what the controller holds: (wish, u_h, v_h)."""
        f, k, N = self.faults, self.k, self.N
        t = k * PERIOD
        slots = self.op_sent.shape[0]
        if k % self.operator_every == 0:
            wish = self.ops.desired(t)
            d = np.clip(self.ops.deflection_of(wish, q_seen, v_seen), -1.0, 1.0)
            lost = self.rng.random(N) < f.operator_loss
            lost |= (k >= f.blackout_at) & (k < f.blackout_at + f.blackout_periods)
            slot = (k + f.operator_delay) % slots
            cols = np.arange(N)
            self.op_deflection[slot, :, cols] = d.T
            self.op_sent[slot, cols] = ~lost
            self.op_time[slot, cols] = t
        here = k % slots
        arrived = self.op_sent[here]
        if arrived.any():
            self.cmd_deflection[:, arrived] = self.op_deflection[here][:, arrived]
            self.cmd_t[arrived] = self.op_time[here][arrived]
            self.cmd_at[arrived] = k
            self.has_cmd |= arrived
            self.op_sent[here] = False
        fresh = self.has_cmd & ((k - self.cmd_at) <= self.stale_periods)
        sent_wish = self.ops.desired(self.cmd_t)
        q_d = np.where(self.has_cmd, sent_wish.q, q_seen)
        zero = np.zeros_like(q_d)
        wish = DesiredBatch(q_d, np.where(fresh, sent_wish.q_dot, zero), np.where(fresh, sent_wish.q_ddot, zero))
        last = self.wish
        if last is not None and all(np.array_equal(a, b) for a, b in ((last.q, wish.q), (last.q_dot, wish.q_dot),
                                                                       (last.q_ddot, wish.q_ddot))):
            wish = last                 # the same wish: the controller keeps its projected references
        self.wish = wish
        kp = self.ops.kp
        d = np.where(fresh, self.cmd_deflection, 0.0)
        return wish, kp * d, np.where(fresh, intent_of(kp, d), 0.0)

    def period(self, controller_alive: np.ndarray | None = None) -> None:
        f, k, N = self.faults, self.k, self.N
        alive = (k < f.kill_at) & ~((k >= f.hang_at) & (k < f.hang_at + f.hang_periods))
        if controller_alive is not None:
            alive &= controller_alive
        first_fault = (k == f.kill_at) | (k == f.hang_at)
        if first_fault.any():
            self.approach_at_fault[first_fault] = self.oracle.closing_speed(self.q, self.v)[first_fault]
        runs = alive & ~self.estopped
        trip = runs & ~self.armed.all(axis=0)
        if trip.any():
            self.estopped |= trip
            self.armed[:, trip] = False
            self.torque[:, trip] = 0.0
            runs &= ~trip
        q_fb, v_fb = self.sample(f.feedback)
        wish, u_h, v_h = self.operator(q_fb, v_fb)
        if runs.any():
            u_s, authority, finite = self.controller.step(
                q_fb, None if self.output_feedback else v_fb, wish, u_h, v_h, runs,
                None if self.output_feedback else f.feedback + f.transit)
            bad = runs & ~finite
            if bad.any():                          # NonFiniteCommand: the daemon stops the robot
                self.nonfinite |= bad
                self.estopped |= bad
                self.armed[:, bad] = False
                self.torque[:, bad] = 0.0
                runs &= ~bad
            self.acted |= runs & (authority > 0)
            tau = self.model.wheel_map.wheel_torques_batch(q_fb[2], np.nan_to_num(u_s))
            delivered = runs[None, :] & (self.rng.random((3, N)) >= f.torque_loss)
            slot = (k + f.transit) % self.pending.shape[0]
            cols = np.arange(N)
            self.pending[slot, :, cols] = np.where(delivered, tau, self.pending[slot, :, cols].T).T
            self.pending_mask[slot, :, cols] |= delivered.T
        here = k % self.pending.shape[0]
        for sub in range(PHYSICS_SUBSTEPS):
            now = k * self.period_ms + sub * self.physics_ms
            trip = self.armed & (now - self.fed_ms > self.watchdog_ms)
            if trip.any():
                self.armed &= ~trip
                self.torque[trip] = 0.0
            if sub == 0:
                due = self.pending_mask[here] & self.armed
                self.torque = np.where(due, self.pending[here], self.torque)
                self.fed_ms = np.where(due, now, self.fed_ms)
                self.pending_mask[here] = False
            self.q, self.v = self.plant.step(self.q, self.v, self.torque, ~self.armed, self.physics_ms * 1e-3)
            m = self.oracle.margin(self.q)
            lower = m < self.min_margin
            if lower.any():
                self.min_margin = np.where(lower, m, self.min_margin)
                self.min_margin_t = np.where(lower, (now + self.physics_ms) * 1e-3, self.min_margin_t)
        self.k += 1
        n = self.model.n
        slot = self.k % self.history.shape[0]
        self.history[slot, :n], self.history[slot, n:] = self.q, self.v

    def run(self, periods: int) -> "FaultyLoop":
        for _ in range(periods):
            self.period()
        return self

    def run_to_rest(self, limit: float = 3.0) -> "FaultyLoop":
        """Periods on, until every robot whose controller is gone (killed, estopped) is disarmed and at
        rest, at most `limit` s; controllers still alive keep running (with their operators). The run is
        over: a kill or a hang due from now on does not come (as in `sharedctl demo`, whose faults fire
        within its duration)."""
        f, k = self.faults, self.k
        self.faults = f.replace(kill_at=np.where(f.kill_at >= k, NEVER, f.kill_at),
                                hang_at=np.where(f.hang_at >= k, NEVER, f.hang_at))
        for _ in range(int(limit / PERIOD)):
            gone = (self.k >= self.faults.kill_at) | self.estopped
            moving = gone & (self.armed.any(axis=0) | np.any(np.abs(self.v) >= 1e-3, axis=0))
            if not moving.any():
                break
            self.period()
        return self

    def result(self) -> LoopResult:
        return LoopResult(self.min_margin.copy(), self.min_margin_t.copy(), self.estopped.copy(), self.acted.copy(),
                          self.nonfinite.copy(), np.linalg.norm(self.v, axis=0), self.q.copy(), self.v.copy(),
                          self.approach_at_fault.copy())


def _oracle_margins(K, T, starts, q, out):
    """Oracle.margin for every robot (columns of q), into `out`: max over polytopes (rows
    starts[r]:starts[r + 1]) of the min over rows of −(k q + t), NaN where q has one."""
    for i in range(q.shape[1]):
        best = -np.inf
        for r in range(starts.shape[0] - 1):
            least = np.inf
            for j in range(starts[r], starts[r + 1]):
                dot = 0.0
                for c in range(K.shape[1]):
                    dot += K[j, c] * q[c, i]
                value = -(dot + T[j])
                if value != value:
                    least = value
                    break
                if value < least:
                    least = value
            if least != least:
                best = least
                break
            if least > best:
                best = least
        out[i] = best


_margins = numba.njit(cache=True)(_oracle_margins) if numba is not None else _oracle_margins
