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

from .base import cached_gain
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

    def _gains(self, n):
        ka, kb = cached_gain(self, "Ka", n), cached_gain(self, "Kb", n)
        checked = self.__dict__.get("_checked_gains")
        if checked is not None and checked[0] is ka and checked[1] is kb:
            return checked
        if np.any(ka <= 1.0):
            raise ValueError("observer needs K_a > 1 so that K_c = K_a − I is positive")
        kc = ka - 1.0
        kc.flags.writeable = False
        self.__dict__["_checked_gains"] = (ka, kb, kc)
        return ka, kb, kc

    def velocity(self, q: np.ndarray, state: np.ndarray) -> np.ndarray:
        """v̂ = β_o + K_a (q − q̂)."""
        n = q.size
        ka = cached_gain(self, "Ka", n)
        return state[n:] + ka * (q - state[:n])

    def derivative(self, q: np.ndarray, state: np.ndarray) -> np.ndarray:
        n = q.size
        ka, kb, kc = self._gains(n)
        q_tilde = q - state[:n]
        beta = state[n:]
        return np.concatenate([beta + ka * q_tilde, kb * smooth_sign(q_tilde, self.sign_width) + kc * q_tilde])
