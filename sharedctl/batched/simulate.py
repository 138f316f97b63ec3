"""`simulate_batch`: simulator.simulate for N robots at once.

Each robot of the batch follows simulator.simulate's algorithm step for step (step.py): the
sharing function sampled and held over each step, one joint RK4 step of plant, law, θ̂ and
observer, the same re-initialisation and stopping rules. Robots are independent columns of
(…, N) arrays; a robot that stops (its RK stage left the active group, or its state turned
non-finite) is dropped from the arrays and its figures are kept.

The batch is processed in chunks of `chunk` robots, each chunk start to finish: the arrays of a
chunk stay in cache, and results do not depend on the chunk size.
"""
from __future__ import annotations

import numpy as np

from ..controllers import CertaintyEquivalentLaw, CompositeAdaptiveLaw, OutputFeedbackBarrierLaw, OutputFeedbackLaw
from .arbiter import ArbiterArrays
from .backup import BackupTable
from .geometry import GroupTable
from .laws import CertaintyEquivalent, CompositeAdaptive, Observer, OutputFeedback, OutputFeedbackBarrier
from .problem import BatchProblem, StateLayout
from .results import BatchResult, Recording, Tally, finish
from .step import StepKernel


def simulate_batch(problem: BatchProblem, duration: float, dt: float, record: bool = False,
                   chunk: int = 8192) -> BatchResult:
    """Run every robot of `problem` for `duration` s with step `dt` (simulator.simulate's algorithm).

    Returns per-robot summaries (the fields of metrics.summarize); with `record`, also every
    robot's Trace (`result.trace(i, model)`).
    """
    if not (dt > 0 and duration > 0 and np.isfinite(duration) and np.isfinite(dt)):
        raise ValueError("duration and dt must be positive and finite")
    _keep_heap_mapped()
    engine = Engine(problem, dt)
    steps = int(round(duration / dt))
    N = problem.size
    recording = Recording(steps, engine.n, engine.k, N) if record else None
    out = _Totals(N, engine.k)
    chunk = max(1, int(chunk))
    with np.errstate(all="ignore"):
        for start in range(0, N, chunk):
            ids = np.arange(start, min(N, start + chunk))
            engine.run(problem.take(ids), ids, steps, out, recording)
    return finish(dt, out.tally, out.switches, out.group_switches, out.finite, recording, problem.theta)


def _keep_heap_mapped() -> None:
    """Allocate and free one 16 MiB block, so that the C allocator keeps a step's memory mapped.

    Every numpy temporary is a malloc; glibc hands the top of its heap back to the kernel as soon
    as more than its trim threshold (128 KiB at start-up) is free, so each step's temporaries were
    faulted in afresh (~130 page faults per step at 2048 robots, ~13 % of the time). Freeing a
    block that glibc had to mmap raises its mmap threshold to that size and its trim threshold to
    twice it (glibc's dynamic thresholds, mallopt(3)); other allocators merely see 16 MiB come and go.
    The block is never written, so no page of it is touched.
    """
    np.empty(16 * 1024 * 1024 // 8)


def _vector_law(law, n: int, n_theta: int):
    if isinstance(law, CertaintyEquivalentLaw):
        return CertaintyEquivalent(law, n)
    if isinstance(law, CompositeAdaptiveLaw):
        return CompositeAdaptive(law, n, n_theta)
    if isinstance(law, OutputFeedbackLaw):
        return OutputFeedback(law, n)
    if isinstance(law, OutputFeedbackBarrierLaw):
        return OutputFeedbackBarrier(law, n)
    raise TypeError(f"no batched form of {type(law).__name__}")


class Engine:
    """What every chunk shares: the group table, the vectorised laws, the backup governor, the state layout."""

    def __init__(self, problem: BatchProblem, dt: float):
        model, controller = problem.model, problem.controller
        self.n, self.k, self.dt = model.n, model.n_theta, dt
        self.feasible, self.sharing, self.mode = problem.feasible, problem.sharing, problem.sharing.mode
        self.shape, self.lam = problem.reference, controller.tracking.lam
        self.table = GroupTable.of(problem.feasible)
        self.backup = None if problem.backup is None else BackupTable.of(problem.backup, problem.feasible, self.table)
        tracking = _vector_law(controller.tracking, self.n, self.k)
        hazard = (tracking if controller.hazard is controller.tracking
                  else _vector_law(controller.hazard, self.n, self.k))
        self.laws = (tracking, hazard)                        # by LawRole
        self.distinct = list(dict.fromkeys(self.laws))
        self._serves = np.array([[law is self.laws[r] for r in (0, 1)] for law in self.distinct])
        self.law_of_role = np.array([self.distinct.index(law) for law in self.laws])   # by LawRole: distinct index
        self.state_size = np.array([law.state_size for law in self.laws])
        self.projects = np.array([law.projects_estimate for law in self.laws])
        self._own = np.array([controller.owns(law) for law in (controller.tracking, controller.hazard)])  # by LawRole
        self.observer = Observer(controller.observer, self.n) if controller.observer else None
        self.layout = StateLayout(self.n, self.k, int(self.state_size.max()), 2 * self.n if self.observer else 0)
        self.kernel = StepKernel(self)

    def runs(self, index: int, roles: np.ndarray) -> np.ndarray:
        """Which of `roles` (LawRole values, −1 for none) run the distinct law `index`."""
        return (roles >= 0) & self._serves[index][np.maximum(roles, 0)]

    def owns(self, roles: np.ndarray) -> np.ndarray:
        """Which of `roles` (LawRole values, −1 for none) run a law of the configuration
        (MachineController.owns)."""
        return (roles >= 0) & self._own[np.maximum(roles, 0)]

    def run(self, problem: BatchProblem, ids, steps: int, out: "_Totals", recording) -> None:
        L, N = self.layout, ids.size
        Y = np.zeros((L.rows, N))
        Y[L.q], Y[L.v], Y[L.theta] = problem.q0, problem.v0, problem.theta_hat0
        if self.observer:
            Y[L.obs] = self.observer.initial_state(problem.q0)
        arbiter = ArbiterArrays.initial(self.sharing, N, self.table.row_K.shape[0])
        fleet = Fleet(ids, Y, arbiter, problem.operators, problem.theta, Tally.empty(N, self.k))
        for k in range(steps):
            if fleet.size == 0:
                break
            stopping = self.kernel.step(fleet, k, steps, recording)
            if stopping is not None:
                cols, finite = stopping
                out.keep(fleet, cols, finite)
                fleet.drop(cols)
        out.keep(fleet, np.arange(fleet.size), np.ones(fleet.size, bool))


class _Totals:
    """The whole batch's figures, filled as robots stop or chunks end."""

    def __init__(self, N: int, n_theta: int):
        self.tally = Tally.empty(N, n_theta)
        self.switches, self.group_switches = np.zeros(N, np.int64), np.zeros(N, np.int64)
        self.finite = np.ones(N, bool)

    def keep(self, fleet: "Fleet", cols: np.ndarray, finite: np.ndarray) -> None:
        if cols.size == 0:
            return
        ids = fleet.ids[cols]
        part = fleet.tally.take(cols)
        for name in part.__dataclass_fields__:
            getattr(self.tally, name)[..., ids] = getattr(part, name)
        self.switches[ids] = fleet.arbiter.switches[cols]
        self.group_switches[ids] = fleet.arbiter.group_switches[cols]
        self.finite[ids] = finite


class Fleet:
    """The robots of a chunk still running: state (D, N), arbiter memory, law bookkeeping."""

    def __init__(self, ids, Y, arbiter, operators, theta, tally):
        N = ids.size
        self.ids, self.Y, self.arbiter = ids, Y, arbiter
        self.law_role = np.full(N, -1)             # the law last engaged (simulator's `law`), −1 for none
        self.engaged_before = np.zeros(N, bool)
        self.has_state = np.zeros(N, bool)         # the law's filters are live (law_state.size > 0)
        self.share = np.zeros(N)                   # the governor's last λ, where its next search starts
        self.operators, self.theta, self.tally = operators, theta, tally

    @property
    def size(self) -> int:
        return self.ids.size

    def drop(self, cols) -> None:
        keep = np.ones(self.size, bool)
        keep[cols] = False
        self.ids, self.Y = self.ids[keep], self.Y[:, keep]
        self.arbiter = self.arbiter.take(keep)
        self.law_role, self.engaged_before, self.has_state = (self.law_role[keep], self.engaged_before[keep],
                                                              self.has_state[keep])
        self.share = self.share[keep]
        self.operators, self.theta, self.tally = self.operators.take(keep), self.theta[:, keep], self.tally.take(keep)
