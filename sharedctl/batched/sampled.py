"""`SharedController.step` for every robot of a batch: the sampled controller the daemon runs.

The continuous batch (simulate.py) integrates plant and law together; a real controller samples
(q, q̇) every period, holds its command and advances its own states by one forward-Euler step.
`SampledBatch.step` is shared_controller.SharedController.step over the batch, rule for rule:

1. with state feedback and a loop delay of L periods (feedback age + command transit), the
   sample is first predicted over the delay by the commands this controller sent meanwhile
   (shared_controller.predict: the model's acceleration at each period's start, held; compiled
   robot by robot where numba is installed, plant.predict_rings);
2. the sharing function at the sample (StepKernel.decide; every group's selection value only for
   the robots whose group is chosen anew, as the scalar controller's _EveryGroupOnDemand) and the
   law (re)initialisation (StepKernel.engage) — on the robots whose sample lies inside their active
   group (`lawful`);
   an engaged robot outside it (possible only sampled, with delay) gets the recovery force
   (SharedController.recovery_force) and its law is disengaged;
3. u_s = w_h u_h + w_f u_f, made backup-safe by the governor (StepKernel.rates at its first
   stage, which is the law evaluated at the sample);
4. θ̂ += dt·θ̂̇ under full machine authority (held where the governor moved u_s), projected onto
   the law's box; the law's filters and the observer += dt · their rates, the filters seeing the
   applied u_s.

Robots that do not run this period (`running` false: a hung or killed controller, an estop) keep
their controller state exactly. A robot whose command or state turns non-finite is reported
(`SharedController.step` raises NonFiniteCommand there; the daemon then stops the robot).

Limits: the omni robot only (plant.py); under output feedback with a loop delay the judged state
of the backup checks (shared_controller.judged_state's uncertain prediction) has no batched form
yet — refused with a ValueError.
"""
from __future__ import annotations

import numpy as np

from ..shared_controller import HISTORY, SharedController
from .arbiter import HUMAN, MACHINE, ArbiterArrays
from .laws import gather, scatter
from .operators import DesiredBatch
from .plant import acceleration, predict_rings_compiled
from .problem import BatchProblem
from .results import Tally
from .simulate import Engine, Fleet


class SampledBatch:
    """The sampled shared controller for N robots (one scenario), period `dt` seconds."""

    def __init__(self, problem: BatchProblem, dt: float, compiled: bool | None = None):
        """`compiled`: the prediction over the loop delay robot by robot with numba (plant.predict_rings;
        None: where it is installed; True: required; False: the numpy code of `predict`)."""
        if compiled and predict_rings_compiled is None:
            raise ValueError("a compiled prediction needs numba (the montecarlo extra)")
        self.compiled = predict_rings_compiled is not None if compiled is None else bool(compiled)
        if not (dt > 0 and np.isfinite(dt)):
            raise ValueError("the control period must be positive and finite")
        self.problem = problem
        self.engine = Engine(problem, dt)
        self.kernel = self.engine.kernel
        self.dt = dt
        e, N = self.engine, problem.size
        L = e.layout
        Y = np.zeros((L.rows, N))
        Y[L.q], Y[L.v], Y[L.theta] = problem.q0, problem.v0, problem.theta_hat0
        if e.observer:
            Y[L.obs] = e.observer.initial_state(problem.q0)
        arbiter = ArbiterArrays.initial(e.sharing, N, e.table.row_K.shape[0])
        self.fleet = Fleet(np.arange(N), Y, arbiter, problem.operators, problem.theta, Tally.empty(N, e.k))
        self.sent = np.zeros((e.n, N * HISTORY))       # the last commands u_s: robot i's ring at [i·H, (i+1)·H)
        self.sent_count = np.zeros(N, dtype=np.int64)  # commands sent so far (the ring's write position mod HISTORY)
        self.recovery_damping = SharedController.recovery_damping       # N s/m
        self.recovery_stiffness = SharedController.recovery_stiffness   # N/m

    @property
    def size(self) -> int:
        return self.fleet.size

    # ------------------------------------------------------------------------------
    def step(self, q: np.ndarray, v: np.ndarray | None, wish: DesiredBatch, u_h: np.ndarray, intent: np.ndarray,
             running: np.ndarray, lag: np.ndarray | None = None):
        """One sample for the robots `running` (N,) bool; returns (u_s (n, N), authority (N,), finite (N,)).

        q, v (n, N): the sample (v ignored under output feedback); wish, u_h (n, N), intent (N,): the
        operator's input as the controller holds it; lag (N,) int: the loop delay in periods
        (SharedController.step's `delay` / dt). Columns not running get u_s = NaN and keep their state."""
        e, fleet, dt = self.engine, self.fleet, self.dt
        L, N = e.layout, fleet.size
        if e.observer is not None and lag is not None and np.any(lag > 0):
            raise ValueError("output feedback with a loop delay has no batched form (judged_state's prediction)")
        saved = _snapshot(fleet) if not running.all() else None
        q = np.array(q, dtype=float)
        v = np.zeros_like(q) if (v is None or e.observer) else np.array(v, dtype=float)
        if e.observer is None and lag is not None:
            q, v = self.predict(q, v, lag)
        Y = fleet.Y
        Y[L.q], Y[L.v] = q, v
        theta_hat, law_state = Y[L.theta], Y[L.law_state]
        v_used = e.observer.velocity(q, Y[L.obs]) if e.observer else v
        groups, _, _, dec = self.kernel.decide(fleet, q, v_used, wish, u_h, intent, dt, on_demand=True)
        engaged = (dec.authority != HUMAN) & (dec.group >= 0)
        g = np.maximum(dec.group, 0)
        x_group = groups.rows.x[e.table.group_rows[g].T, np.arange(N)]      # (n, N): the active group's rows at q
        lawful = engaged & np.all(x_group < 0.0, axis=0)
        recovering = engaged & ~lawful
        self.kernel.engage(fleet, dec, lawful, groups, theta_hat, law_state)
        u_extra = None
        if recovering.any():
            excess = np.maximum(x_group + e.shape.epsilon, 0.0)
            K = e.table.K[g]                                                 # (N, n, n)
            push = np.einsum("nji,jn->in", K, excess)
            force = -self.recovery_damping * v_used - self.recovery_stiffness * push
            u_extra = np.where(recovering, dec.machine_weight * force, 0.0)
        plan = self.kernel.plan(lawful, dec, (wish,))
        machine = dec.authority == MACHINE
        escaped = np.zeros(N, bool)
        rate, _, _, u_s = self.kernel.rates(fleet, Y, wish, plan, 0, dec, machine, escaped, u_h, record=True,
                                            u_extra=u_extra)
        # forward Euler on the controller's own states (not on q, q̇: those are samples)
        Y[L.theta] += dt * rate[L.theta]
        projecting = (fleet.law_role >= 0) & e.projects[np.maximum(fleet.law_role, 0)] & machine
        if projecting.any():
            th = Y[L.theta]
            for index, law in enumerate(e.distinct):
                cols = np.flatnonzero(projecting & e.runs(index, fleet.law_role))
                if cols.size:
                    sel = None if cols.size == N else cols
                    scatter(th, sel, law.project(gather(th, sel)))
        live = lawful & fleet.has_state
        if live.any():
            Y[L.law_state] += dt * np.where(live, rate[L.law_state], 0.0)
        if e.observer:
            Y[L.obs] += dt * rate[L.obs]
        finite = np.isfinite(u_s).all(axis=0) & np.isfinite(Y[L.theta]).all(axis=0) \
            & np.isfinite(Y[L.law_state]).all(axis=0)
        if saved is not None:
            _restore(fleet, saved, ~running)
        moved = running & finite
        cols = np.flatnonzero(moved)
        self.sent[:, cols * HISTORY + self.sent_count[cols] % HISTORY] = u_s[:, cols]
        self.sent_count[cols] += 1
        u_s = np.where(moved, u_s, np.nan)
        return u_s, np.where(moved, dec.authority, -1), finite | ~running

    def predict(self, q: np.ndarray, v: np.ndarray, lag: np.ndarray):
        """shared_controller.predict per robot over its last min(lag, sent) commands (oldest first); with
        `compiled`, plant.predict_rings robot by robot (the same floats)."""
        use = np.minimum(np.asarray(lag, dtype=np.int64), np.minimum(self.sent_count, HISTORY))
        longest = int(use.max()) if use.size else 0
        if longest == 0:
            return q, v
        if self.compiled:
            q, v = np.array(q, dtype=float, order="C"), np.array(v, dtype=float, order="C")
            predict_rings_compiled(np.ascontiguousarray(self.fleet.theta, dtype=float), self.sent, self.sent_count, use,
                                   HISTORY, float(self.dt), q, v)
            return q, v
        # the robots with commands to predict over, longest first: those still predicting at each
        # iteration j (use ≥ longest − j) are then a prefix of them
        cols = np.flatnonzero(use)
        cols = cols[np.argsort(-use[cols], kind="stable")]
        use = use[cols]
        index = cols * HISTORY + self.sent_count[cols] - longest      # + j, mod HISTORY within each ring
        theta = self.fleet.theta[:, cols]
        qc, vc = q[:, cols], v[:, cols]
        half, dt = 0.5 * self.dt * self.dt, self.dt
        a = np.empty_like(qc)
        descending = -use
        for j in range(longest):
            m = int(np.searchsorted(descending, j - longest, side="right"))   # use ≥ longest − j
            ring = cols[:m] * HISTORY + (index[:m] - cols[:m] * HISTORY + j) % HISTORY
            u = self.sent.take(ring, axis=1)
            am, vm = a[:, :m], vc[:, :m]
            acceleration(theta[:, :m], vm, u, am)
            step = qc[:, :m] + dt * vm
            step += half * am
            qc[:, :m] = step
            vm += dt * am
        q, v = q.copy(), v.copy()
        q[:, cols], v[:, cols] = qc, vc
        return q, v


def _snapshot(fleet: Fleet) -> tuple:
    arbiter = ArbiterArrays(*(getattr(fleet.arbiter, f).copy() for f in fleet.arbiter.__dataclass_fields__))
    return (fleet.Y.copy(), arbiter, fleet.law_role.copy(), fleet.engaged_before.copy(), fleet.has_state.copy())


def _restore(fleet: Fleet, saved: tuple, keep: np.ndarray) -> None:
    """Put back the state of columns `keep` as it was before the step."""
    Y, arbiter, law_role, engaged_before, has_state = saved
    fleet.Y[:, keep] = Y[:, keep]
    for f in arbiter.__dataclass_fields__:
        getattr(fleet.arbiter, f)[keep] = getattr(arbiter, f)[keep]
    fleet.law_role[keep] = law_role[keep]
    fleet.engaged_before = np.where(keep, engaged_before, fleet.engaged_before)
    fleet.has_state[keep] = has_state[keep]
