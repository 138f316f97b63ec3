"""`cbf`: a control-barrier-function QP safety filter over the operator's force (relative degree 2).

For the polytope filtered against, {K q + T ≤ 0} with unit rows, every row j has the barrier
h_j(q) = −(k_jᵀ q + t_j) − δ (≥ 0 at least δ inside the face). Position constraints have relative
degree 2 in the force: ḣ_j = −k_jᵀ q̇, ḧ_j = −k_jᵀ q̈ with q̈ = M̂⁻¹(u − Ĉ q̇ − ĝ) from (1). The
exponential (high-order) CBF condition

    ḧ_j + k1 ḣ_j + k0 h_j ≥ 0,   k1 = 2ω, k0 = ω²   (both poles at −ω)

is linear in u:  k_jᵀ M̂⁻¹ u ≤ k_jᵀ M̂⁻¹ (Ĉ q̇ + ĝ) − k1 k_jᵀ q̇ + k0 h_j,  i.e. A u ≤ b. The filter
solves, every control period,

    u = argmin ½ |u − u_h|²   subject to   A u ≤ b

with quadprog (an exact dense active-set solver: 3 unknowns, one row per face). Where the
constraints are inactive u = u_h exactly. h_j stays ≥ 0 whenever ψ_j = ḣ_j + ω h_j ≥ 0 at the
start (forward invariance of the high-order CBF), up to the sampling of the held force.

**Model.** M̂, Ĉ, ĝ are evaluated at nominal parameters — by default the plant's true θ: the
filter is given the exact model, which the shared law does not need (its θ̂ starts at 0 and
adapts). Pass `theta` to give it an estimate instead.

**Unions of polytopes (switching rule).** The filter enforces one polytope at a time, r. A
polytope is *admissible* at (q, q̇) when q is inside it and every row has ψ_j ≥ 0 (the
barrier's own admissible initial set, so switching to it cannot break invariance). Each sample:
keep r while it is admissible, unless another admissible polytope has a margin (smallest
slack, metres) larger by more than `hysteresis` (5 cm) — then switch to the admissible polytope
of largest margin. If r is not admissible and another is, switch to the best admissible one;
if none is, keep r. At the start r is the containing polytope of largest margin.

**Infeasibility.** Without force limits the QP is infeasible only when two faces' conditions
contradict (a corridor narrower than the braking room). Then the constraints are softened by
one slack s ≥ 0 (A u − s ≤ b, cost ½ρ s², ρ = 10⁶) and the step's residual max(A u − b) > 0
says so.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import quadprog

from ..constraints import FeasibleSet
from .strategy import Command, NominalModel, Strategy, checked

SLACK_WEIGHT = 1.0e6


@dataclass(frozen=True)
class BarrierConstraints:
    """A u ≤ b for one polytope at one state, and the first-order barrier ψ_j = ḣ_j + ω h_j."""

    A: np.ndarray
    b: np.ndarray
    psi: np.ndarray


@dataclass
class CbfSafetyFilter(Strategy):
    feasible: FeasibleSet
    nominal: NominalModel
    bandwidth: float = 5.0        # ω, rad/s: k1 = 2ω, k0 = ω²
    buffer: float = 0.01          # δ, m: the barrier's zero set lies δ inside each face
    hysteresis: float = 0.05      # m: margin advantage needed to switch polytope
    tolerance: float = 1.0e-9     # N: |u − u_h| below this counts as "passed unchanged"
    name: str = "cbf"

    def constraints(self, region: int, q: np.ndarray, v: np.ndarray) -> BarrierConstraints:
        poly = self.feasible.regions[region]
        w = self.bandwidth
        h = -(poly.K @ q + poly.T) - self.buffer
        h_dot = -(poly.K @ v)
        KMinv = np.linalg.solve(self.nominal.mass(q).T, poly.K.T).T     # K M̂⁻¹
        A = KMinv
        b = KMinv @ self.nominal.bias(q, v) + 2.0 * w * h_dot + w * w * h
        return BarrierConstraints(A, b, h_dot + w * h)

    def admissible(self, region: int, q, v) -> bool:
        return self.feasible.regions[region].contains(q) and bool(np.all(self.constraints(region, q, v).psi >= 0.0))

    def select_region(self, current: int | None, q, v) -> int:
        """The switching rule for unions (see the module docstring)."""
        if len(self.feasible.regions) == 1:
            return 0
        margins = self.feasible.region_margins(q)
        if current is None:
            return int(np.argmax(margins))
        admissible = [r for r in range(len(self.feasible.regions)) if self.admissible(r, q, v)]
        if not admissible:
            return current
        best = max(admissible, key=lambda r: margins[r])
        if current not in admissible or margins[best] > margins[current] + self.hysteresis:
            return best
        return current

    def initial_state(self, q0, v0):
        return self.select_region(None, np.asarray(q0, float), np.asarray(v0, float))

    def step(self, state, q, v, operator, dt):
        u_h = np.asarray(operator.force, float)
        region = self.select_region(state, q, v)
        con = self.constraints(region, q, v)
        u = self.solve(u_h, con.A, con.b)
        residual = float(np.max(con.A @ u - con.b))
        passed = bool(np.max(np.abs(u - u_h)) <= self.tolerance)
        return region, Command(checked(u), u_h, passed, region, residual)

    @staticmethod
    def solve(u_h: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
        """argmin ½|u − u_h|² s.t. A u ≤ b (quadprog: min ½xᵀGx − aᵀx s.t. Cᵀx ≥ b)."""
        if np.all(A @ u_h <= b):
            return u_h.copy()                      # inactive: the operator's force passes exactly
        n = u_h.size
        try:
            return quadprog.solve_qp(np.eye(n), u_h, -A.T, -b, 0)[0]
        except ValueError:                         # "constraints are inconsistent": soften with one slack
            G = np.eye(n + 1)
            G[n, n] = SLACK_WEIGHT
            C = np.vstack([np.hstack([-A, np.ones((A.shape[0], 1))]), np.eye(1, n + 1, n)])
            lower = np.concatenate([-b, [0.0]])
            return quadprog.solve_qp(G, np.append(u_h, 0.0), C.T, lower, 0)[0][:n]
