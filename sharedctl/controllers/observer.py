"""Velocity observer (paper (40)) for the output-feedback law, run on q.

    q̂̇ = β_o + K_a q̃,   β̇_o = K_b sgn(q̃) + K_c q̃,   q̃ = q − q̂,   v̂ = β_o + K_a q̃,

with K_c = K_a − I (paper, after (42)) so that s = q̃̇ + q̃ obeys ṡ = q̈ − K_b sgn(q̃) − K_c s (43):
s and q̃ go to zero when K_b exceeds bounds on |q̈| and its derivative. The paper writes
the observer in each group's z coordinates and maps ż̂ back with (38); we run it once on
q (the same equations, the measured signal being q instead of z), because q̈ is bounded
by the robot's physics while z̈ grows without bound near a face, and one observer serves
every group. v̂ then gives each group ẋ̂ = K v̂ and ż̂ by (9). sgn is tanh(·/φ).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..short_vectors import floats
from .base import cached_gain_floats
from .smooth_sign import smooth_sign


@dataclass
class VelocityObserver:
    """(40). State: [q̂, β_o]."""

    Ka: float | list[float] = 60.0
    Kb: float | list[float] = 4.0
    sign_width: float = 0.002

    def initial_state(self, q0: np.ndarray, v0: np.ndarray | None = None) -> np.ndarray:
        """q̂(0) = q(0); β_o(0) = v̂(0), the best prior on the initial velocity (0 at rest)."""
        v0 = np.zeros_like(q0) if v0 is None else v0
        return np.concatenate([q0, v0])

    def _gains(self, n) -> tuple[tuple, tuple, tuple]:
        """(K_a, K_b, K_c = K_a − I) as tuples of floats, validated once per change of the gains."""
        ka, kb = cached_gain_floats(self, "Ka", n), cached_gain_floats(self, "Kb", n)
        checked = self.__dict__.get("_checked_gains")
        if checked is not None and checked[0] is ka and checked[1] is kb:
            return checked
        if any(k <= 1.0 for k in ka):
            raise ValueError("observer needs K_a > 1 so that K_c = K_a − I is positive")
        self.__dict__["_checked_gains"] = (ka, kb, tuple(k - 1.0 for k in ka))
        return self.__dict__["_checked_gains"]

    def velocity(self, q: np.ndarray, state: np.ndarray) -> np.ndarray:
        """v̂ = β_o + K_a (q − q̂) (on Python floats)."""
        n = len(q)
        ka, state = cached_gain_floats(self, "Ka", n), floats(state)
        return np.array([b + k * (qj - qh) for b, k, qj, qh in zip(state[n:], ka, floats(q), state[:n])])

    def derivative(self, q: np.ndarray, state: np.ndarray) -> np.ndarray:
        """[q̂̇, β̇_o] of (40) (on Python floats)."""
        n = len(q)
        ka, kb, kc = self._gains(n)
        state = floats(state)
        q_tilde = [qj - qh for qj, qh in zip(floats(q), state[:n])]
        sign = smooth_sign(np.array(q_tilde), self.sign_width).tolist()
        return np.array([b + k * e for b, k, e in zip(state[n:], ka, q_tilde)]
                        + [k * sg + c * e for k, sg, c, e in zip(kb, sign, kc, q_tilde)])
