"""What every machine law looks like: explicit state in, command and state rate out."""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar, NamedTuple

import numpy as np

from ..constraints import ConstraintGroup
from ..models import EulerLagrangeModel
from ..transform import GroupCoordinates
from .adaptation import Adaptation


class LawOutput(NamedTuple):
    """u_f (generalised force), θ̂̇ (the shared estimate's rate) and the law's own state rate (a named tuple)."""

    u: np.ndarray
    theta_dot: np.ndarray
    state_dot: np.ndarray


class MachineLaw(ABC):
    """A machine controller for one constraint group.

    State feedback laws receive the measured velocity v; the output-feedback law receives
    the observer's v̂ and uses it only where docs/control.md says. The parameter
    estimate θ̂ is shared by all groups (one robot, one θ) and owned by the caller.
    """

    name: str
    #: the configuration (make_controller's kind: "ce", "nce", "of") the law belongs to: a sample
    #: whose u_f comes from a law of another configuration (a fallback) is not the configuration's own
    configuration: ClassVar[str] = ""
    #: λ_q of (11): sets p and the selection Lyapunov value
    lam: float = 1.0
    #: whether θ̂ may be projected onto the model's parameter box after each step (gradient
    #: laws: yes; (13)'s θ̂ is half of an estimate θ̂ + β and its identities forbid it)
    projects_estimate: bool = True
    #: the robust part of the update: leakage onto the trust box, the physical box (adaptation.py);
    #: each law declares it as a field, make_controller passes the scenario's `[gains.adaptation]`
    adaptation: Adaptation = Adaptation()

    @abstractmethod
    def state_size(self, model: EulerLagrangeModel) -> int:
        """Length of the law's own state vector (filters), 0 if none."""

    @abstractmethod
    def initial_state(self, model, group, c: GroupCoordinates, q, v, theta_hat) -> np.ndarray:
        """The law's state when it takes over (its published initial conditions)."""

    @abstractmethod
    def evaluate(self, model, group: ConstraintGroup, c: GroupCoordinates, q, v, theta_hat, state) -> LawOutput:
        """u_f, θ̂̇ and the state rate at one instant (the rate without the applied input: see
        `with_applied_input`)."""

    def with_applied_input(self, state_dot: np.ndarray, u_applied: np.ndarray) -> np.ndarray:
        """The state rate once the input the plant receives, u_s of (46)/(47), is known.

        u_s depends on u_f (the blend), so it is known only after `evaluate`; a law that filters the
        applied input (the composite law's u_n) adds it here. Every caller that integrates a law's
        state calls this with u_s, in every sample and RK stage the law is engaged."""
        return state_dot

    def estimate(self, theta_hat: np.ndarray, state: np.ndarray) -> np.ndarray:
        """The parameter estimate this law currently stands for (θ̂, or θ̂ + β for (13))."""
        return theta_hat

    def project(self, model: EulerLagrangeModel, theta_hat: np.ndarray) -> np.ndarray:
        """θ̂ after a step: projected onto the physical box B when the law projects, else as it is."""
        return model.project(theta_hat, self.adaptation.box(model)) if self.projects_estimate else theta_hat


def cached_gain(owner, name: str, n: int) -> np.ndarray:
    """diag_gain(owner.<name>, n), validated once and kept until the attribute's value changes
    (a per-step constant; read-only, so no caller can alter the cached vector)."""
    value = getattr(owner, name)
    snapshot = value if isinstance(value, (int, float)) else tuple(np.ravel(value).tolist())
    cache = owner.__dict__.setdefault("_gain_cache", {})
    hit = cache.get((name, n))
    if hit is not None and hit[0] == snapshot:
        return hit[1]
    vector = diag_gain(value, n)
    vector.flags.writeable = False
    cache[(name, n)] = (snapshot, vector)
    return vector


def cached_gain_floats(owner, name: str, n: int) -> tuple[float, ...]:
    """cached_gain as a tuple of Python floats (for laws computing on floats)."""
    vector = cached_gain(owner, name, n)
    cache = owner.__dict__.setdefault("_gain_floats_cache", {})
    hit = cache.get((name, n))
    if hit is not None and hit[0] is vector:
        return hit[1]
    values = tuple(vector.tolist())
    cache[(name, n)] = (vector, values)
    return values


def diag_gain(value, n: int) -> np.ndarray:
    """A positive gain given as a scalar or a length-n list, as a vector."""
    arr = np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
    if np.any(arr <= 0) or not np.all(np.isfinite(arr)):
        raise ValueError(f"gain must be positive and finite, got {value!r}")
    return arr
