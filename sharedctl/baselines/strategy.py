"""What every compared strategy is: a sampled step function from (q, q̇, operator input) to a force.

A strategy is "state in, command out", like `SharedController.step`: the comparison loop
(comparison.py) samples (q, q̇) every control period, gives the operator input from the link
(operator_link.py), applies the returned generalised force u until the next sample, and keeps
the strategy's state. This module holds the interface and the two strategies that need no
design of their own:

* `human` — the operator alone: u = u_h (sharing.Mode.HUMAN, without the machine);
* `shared` — the paper's law (46)/(47) with its machine law: `SharedController` as the daemon runs it,
  with the scenario's backup-safe sets (sharedctl/backup.py) when it has a brake model;
* `shared-nobackup` — the same law with `[backup] enabled = false`: the paper's loop, no speed-aware
  sets and no governor, so that the two measure what keeping the fail-safe stop inside Q_a costs.

`mux` (mux.py) and `cbf` (cbf.py) are the alternatives people use today.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..models import EulerLagrangeModel
from ..shared_controller import NonFiniteCommand, OperatorInput, SharedController
from ..sharing import Authority
from ..simulator import ClosedLoop


@dataclass(frozen=True)
class Command:
    """One sample's output.

    `u` is the generalised force to hold; `u_h` the operator's force it started from;
    `operator_in_control` is True when u = u_h (the operator's command passed unchanged);
    `mode` a strategy-specific integer for plots and tests (shared: the authority; mux: the
    selected input; cbf: the polytope filtered against); `residual` the largest constraint
    residual of a QP, max(A u − b) (cbf only, NaN otherwise).
    """

    u: np.ndarray
    u_h: np.ndarray
    operator_in_control: bool
    mode: int = 0
    residual: float = float("nan")


class Strategy(ABC):
    """A sampled controller between the operator and the robot."""

    name: str

    @abstractmethod
    def initial_state(self, q0: np.ndarray, v0: np.ndarray) -> Any:
        """The strategy's memory before the first sample."""

    @abstractmethod
    def step(self, state: Any, q: np.ndarray, v: np.ndarray, operator: OperatorInput, dt: float) -> tuple[Any, Command]:
        """One control period: (next state, command). Raises NonFiniteCommand rather than return a non-finite u."""


class OperatorAlone(Strategy):
    """`human`: the operator's force passes unchanged, u = u_h (the robot is not protected)."""

    name = "human"

    def initial_state(self, q0, v0):
        return None

    def step(self, state, q, v, operator, dt):
        u_h = np.asarray(operator.force, float)
        return None, Command(u_h, u_h, True)


@dataclass
class SharedStrategy(Strategy):
    """`shared`: the paper's sharing law (46)/(47) with the scenario's machine law, sampled like the daemon."""

    controller: SharedController
    theta_hat0: np.ndarray | None = None
    name: str = "shared"

    @staticmethod
    def of(loop: ClosedLoop, backup: bool = True) -> "SharedStrategy":
        """The loop's controller; `backup=False` drops its backup model (`shared-nobackup`)."""
        return SharedStrategy(SharedController(loop.model, loop.feasible, loop.controller,
                                               loop.sharing, loop.reference, loop.backup if backup else None),
                              loop.theta_hat0, "shared" if backup else "shared-nobackup")

    def initial_state(self, q0, v0):
        return self.controller.initial_state(q0, self.theta_hat0)

    def step(self, state, q, v, operator, dt):
        output_feedback = self.controller.machine.observer is not None
        state, out = self.controller.step(state, q, None if output_feedback else v, operator, dt)
        return state, Command(out.u_s, out.u_h, out.authority is Authority.HUMAN, int(out.authority))


def checked(u: np.ndarray) -> np.ndarray:
    """u, or NonFiniteCommand: a non-finite value never reaches the plant."""
    if not np.all(np.isfinite(u)):
        raise NonFiniteCommand("a baseline produced a non-finite force")
    return u


@dataclass(frozen=True)
class NominalModel:
    """M̂, Ĉ, ĝ of a model at a nominal parameter vector θ̂ (the true θ unless told otherwise)."""

    model: EulerLagrangeModel
    theta: np.ndarray

    @staticmethod
    def of(model: EulerLagrangeModel, theta: np.ndarray | None = None) -> "NominalModel":
        return NominalModel(model, np.asarray(model.theta if theta is None else theta, float))

    def mass(self, q):
        return self.model.mass(q, self.theta)

    def bias(self, q, v):
        """Ĉ(q, q̇) q̇ + ĝ(q)."""
        return self.model.coriolis_regressor(q, v, v) @ self.theta + self.model.gravity_regressor(q) @ self.theta

