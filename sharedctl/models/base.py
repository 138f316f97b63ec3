"""The interface every plant model offers the controllers.

A model is M(q) q̈ + C(q, q̇) q̇ + g(q) = u (paper (1)), linear in a parameter vector θ.
The controllers never see θ: they see regressors, i.e. matrices Y with Y θ equal to a
model term. Splitting the regressor into its inertial, Coriolis, gravity and
inertia-rate parts lets one model serve the certainty-equivalent law (12) (needs
M a + C w + g), the non-certainty-equivalent law (13)–(14) (also needs Ṁ b, M p and
C p separately) and the output-feedback law (24)–(25).
"""
from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


_BOX_CACHE: dict = {}      # (lower, upper) tuples → arrays: per-model constants of project()


class EulerLagrangeModel(ABC):
    """A fully actuated Euler–Lagrange system with Ṁ − 2C skew-symmetric."""

    #: number of generalised coordinates
    n: int
    #: number of parameters
    n_theta: int
    #: names of the generalised coordinates, for plots and telemetry
    coordinate_names: tuple[str, ...]
    #: names of the parameters
    parameter_names: tuple[str, ...]
    #: recommended machine-law gains for this plant's inertia scale, per law name
    default_gains: dict = {}
    #: the physical box B, known to contain θ (physically plausible values); adaptive laws project onto it
    theta_lower: tuple = ()
    theta_upper: tuple = ()
    #: the trust box T ⊆ B (the prior: where θ is believed to lie); the laws' leakage pulls the estimate
    #: back into it (controllers/adaptation.py, docs/control.md §11); () for B itself
    theta_band_lower: tuple = ()
    theta_band_upper: tuple = ()

    def project(self, theta_hat: np.ndarray, box: tuple | None = None) -> np.ndarray:
        """Euclidean projection of an estimate onto the parameter box (identity if none is set).

        `box` = (lower, upper) tuples replaces the model's own (a scenario's `[gains.adaptation]`).
        The box is convex and contains θ, so projecting never increases |θ̂ − θ|: the
        θ̃ part of a Lyapunov function cannot grow by it.
        """
        lower, upper = box if box is not None else (self.theta_lower, self.theta_upper)
        if not lower:
            return theta_hat
        bounds = _BOX_CACHE.get((lower, upper))
        if bounds is None:
            bounds = _BOX_CACHE[(lower, upper)] = (np.asarray(lower, float), np.asarray(upper, float))
        return np.minimum(np.maximum(theta_hat, bounds[0]), bounds[1])   # = np.clip, without its per-call overhead

    @property
    @abstractmethod
    def theta(self) -> np.ndarray:
        """The true parameter vector θ of this instance."""

    @abstractmethod
    def mass_regressor(self, q: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Y_M(q, a) with Y_M θ = M(q) a."""

    @abstractmethod
    def coriolis_regressor(self, q: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Y_C(q, v, w) with Y_C θ = C(q, v) w."""

    @abstractmethod
    def gravity_regressor(self, q: np.ndarray) -> np.ndarray:
        """Y_g(q) with Y_g θ = g(q)."""

    @abstractmethod
    def mass_rate_regressor(self, q: np.ndarray, v: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Y_Ṁ(q, v, b) with Y_Ṁ θ = Ṁ(q, v) b, Ṁ the time derivative of M along q̇ = v."""

    # ----- derived quantities -------------------------------------------------
    def regressor(self, q: np.ndarray, v: np.ndarray, w: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Y(q, v, w, a) with Y θ = M(q) a + C(q, v) w + g(q) (the regressor of (11))."""
        return self.mass_regressor(q, a) + self.coriolis_regressor(q, v, w) + self.gravity_regressor(q)

    # ----- the regressors on lists of Python floats, as lists of rows (for the laws' per-sample
    # arithmetic, short_vectors); a model may write them out on floats --------------------------
    def regressor_rows(self, q: list, v: list, w: list, a: list) -> list:
        return self.regressor(np.array(q), np.array(v), np.array(w), np.array(a)).tolist()

    def mass_regressor_rows(self, q: list, a: list) -> list:
        return self.mass_regressor(np.array(q), np.array(a)).tolist()

    def coriolis_regressor_rows(self, q: list, v: list, w: list) -> list:
        return self.coriolis_regressor(np.array(q), np.array(v), np.array(w)).tolist()

    def mass_rate_regressor_rows(self, q: list, v: list, b: list) -> list:
        return self.mass_rate_regressor(np.array(q), np.array(v), np.array(b)).tolist()

    def mass(self, q: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
        """M(q) built column by column from the regressor."""
        th = self.theta if theta is None else theta
        eye = np.eye(self.n)
        return np.column_stack([self.mass_regressor(q, eye[:, j]) @ th for j in range(self.n)])

    def coriolis(self, q: np.ndarray, v: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
        """C(q, v)."""
        th = self.theta if theta is None else theta
        eye = np.eye(self.n)
        return np.column_stack([self.coriolis_regressor(q, v, eye[:, j]) @ th for j in range(self.n)])

    def gravity(self, q: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
        """g(q)."""
        th = self.theta if theta is None else theta
        return self.gravity_regressor(q) @ th

    def mass_rate(self, q: np.ndarray, v: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
        """Ṁ(q, v)."""
        th = self.theta if theta is None else theta
        eye = np.eye(self.n)
        return np.column_stack([self.mass_rate_regressor(q, v, eye[:, j]) @ th for j in range(self.n)])

    def acceleration(self, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Forward dynamics q̈ = M⁻¹(u − C q̇ − g) with the true θ."""
        rhs = u - self.coriolis_regressor(q, v, v) @ self.theta - self.gravity_regressor(q) @ self.theta
        return np.linalg.solve(self.mass(q), rhs)

    def inverse_dynamics(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """u = M a + C q̇ + g with the true θ: the force that gives q̈ = a (inverse of `acceleration`)."""
        return self.regressor(q, v, v, a) @ self.theta

    def input_matrix(self, q: np.ndarray) -> np.ndarray:
        """B(q) mapping actuator efforts τ to generalised forces u = B τ (identity by default)."""
        return np.eye(self.n)
