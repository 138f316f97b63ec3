"""What a batch run needs: the shared scenario and each robot's own initial state and operator.

Shared by every robot of a batch: the feasible set (its groups), the machine controller and
its gains, the sharing parameters, the reference shape and the backup model of the fail-safe
stop (backup.py; None: no governor) — one scenario. Per robot: q(0), q̇(0), θ̂(0), the true
plant parameters θ (the omni robot's mass and inertias may differ) and the operator (kind,
gains, wish or target). Arrays are component-major, (n, N).

The state of a running batch is one (D, N) array, rows [q, q̇, θ̂, law state, observer]:
`StateLayout` names the row ranges, so one RK4 combination updates everything at once.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..backup import BackupModel
from ..constraints import FeasibleSet
from ..reference import ReferenceShape
from ..sharing import SharingParameters
from ..simulator import ClosedLoop, MachineController
from .operators import OperatorBatch, operators_from_models
from .plant import check_model


@dataclass(frozen=True)
class StateLayout:
    """Row ranges of the (D, N) batch state."""

    n: int
    n_theta: int
    law: int          # rows of the largest law state (0 for (12) alone)
    observer: int     # rows of the observer state (0 without one)

    @property
    def q(self) -> slice:
        return slice(0, self.n)

    @property
    def v(self) -> slice:
        return slice(self.n, 2 * self.n)

    @property
    def theta(self) -> slice:
        return slice(2 * self.n, 2 * self.n + self.n_theta)

    @property
    def law_state(self) -> slice:
        start = 2 * self.n + self.n_theta
        return slice(start, start + self.law)

    @property
    def obs(self) -> slice:
        start = 2 * self.n + self.n_theta + self.law
        return slice(start, start + self.observer)

    @property
    def rows(self) -> int:
        return 2 * self.n + self.n_theta + self.law + self.observer


@dataclass(frozen=True)
class BatchProblem:
    """One scenario, N robots."""

    model: object                     # the (shared) plant structure: an OmniRobot
    feasible: FeasibleSet
    controller: MachineController
    sharing: SharingParameters
    reference: ReferenceShape
    q0: np.ndarray                    # (n, N)
    v0: np.ndarray                    # (n, N)
    theta_hat0: np.ndarray            # (n_θ, N)
    theta: np.ndarray                 # (n_θ, N) true parameters
    operators: OperatorBatch
    backup: BackupModel | None = None  # the fail-safe stop the commands are kept safe for (ClosedLoop.backup)

    @property
    def size(self) -> int:
        return self.q0.shape[1]

    def take(self, index) -> "BatchProblem":
        """The robots `index` (slice or index array) of this batch."""
        return BatchProblem(self.model, self.feasible, self.controller, self.sharing, self.reference,
                            self.q0[:, index], self.v0[:, index], self.theta_hat0[:, index], self.theta[:, index],
                            self.operators.take(index), self.backup)

    @staticmethod
    def from_loops(loops: Sequence[ClosedLoop], q0, v0) -> "BatchProblem":
        """N closed loops (sharing one scenario) and their initial states (N, n) → one batch.

        The loops may differ in their human model, θ̂(0) and the plant's parameters; the feasible
        set, controller gains, sharing parameters, reference shape and backup model (or its absence)
        must be the same (ValueError naming the robot and the field otherwise).
        """
        if not loops:
            raise ValueError("a batch needs at least one robot")
        first = loops[0]
        check_model(first.model)
        for i, loop in enumerate(loops[1:], start=1):
            check_model(loop.model)
            _same_feasible(first.feasible, loop.feasible, i)
            for name in ("controller", "sharing", "reference", "backup"):
                if not _same(getattr(first, name), getattr(loop, name)):
                    raise ValueError(f"robot {i}: {name} differs from robot 0 (a batch shares one scenario)")
        n, k = first.model.n, first.model.n_theta
        q0 = _columns(q0, n, len(loops), "q0")
        v0 = _columns(v0, n, len(loops), "v0")
        theta_hat0 = np.stack([np.zeros(k) if lp.theta_hat0 is None else np.asarray(lp.theta_hat0, float)
                               for lp in loops], axis=1)
        theta = np.stack([lp.model.theta for lp in loops], axis=1)
        operators = operators_from_models([lp.human for lp in loops], n)
        return BatchProblem(first.model, first.feasible, first.controller, first.sharing, first.reference,
                            q0, v0, theta_hat0, theta, operators, first.backup)

    @staticmethod
    def replicate(loop: ClosedLoop, q0, v0, operators: OperatorBatch | None = None, theta_hat0=None) -> "BatchProblem":
        """One closed loop, N initial states (N, n); every robot gets `loop.human` unless `operators` is given."""
        check_model(loop.model)
        n, k = loop.model.n, loop.model.n_theta
        q0 = np.asarray(q0, float)
        N = q0.shape[0]
        if operators is None:
            operators = operators_from_models([loop.human], n).take(np.zeros(N, dtype=int))
        elif operators.size != N:
            raise ValueError(f"{operators.size} operators for {N} robots")
        th0 = np.zeros(k) if loop.theta_hat0 is None else np.asarray(loop.theta_hat0, float)
        theta_hat0 = (np.repeat(th0[:, None], N, axis=1) if theta_hat0 is None
                      else _columns(theta_hat0, k, N, "theta_hat0"))
        theta = np.repeat(loop.model.theta[:, None], N, axis=1)
        return BatchProblem(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference,
                            _columns(q0, n, N, "q0"), _columns(v0, n, N, "v0"), theta_hat0, theta, operators,
                            loop.backup)


def _columns(rows, n: int, N: int, name: str) -> np.ndarray:
    arr = np.asarray(rows, dtype=float)
    if arr.shape != (N, n):
        raise ValueError(f"{name} must have shape ({N}, {n}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return np.ascontiguousarray(arr.T)


def _same(a, b) -> bool:
    if a is b:
        return True
    try:
        return bool(a == b)
    except ValueError:   # dataclasses holding numpy arrays
        return repr(a) == repr(b)


def _same_feasible(a: FeasibleSet, b: FeasibleSet, i: int) -> None:
    if a is b:
        return
    same = len(a.regions) == len(b.regions) and all(
        np.array_equal(ra.K, rb.K) and np.array_equal(ra.T, rb.T) for ra, rb in zip(a.regions, b.regions))
    if not same or len(a.groups) != len(b.groups):
        raise ValueError(f"robot {i}: the feasible set differs from robot 0 (a batch shares one scenario)")
