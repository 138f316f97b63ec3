"""The two-link arm with spring-applied joint brakes: the plant the arm's fail-safe stop is measured on.

The dynamics are written out on floats from the physical parameters (M, C, g of
sharedctl/models/planar_arm.py's docstring, which tests/test_models.py checks against the arm's
Lagrangian), not taken from the model object: the controller runs on PlanarArm, the plant on this.

Powered (brakes released) the joints take the drive torques τ: M q̈ + C q̇ + g = τ. Disarmed, the
torque is zero and each joint's brake acts (plus an optional viscous friction b): while joint i
slides, −c_i sgn(q̇_i); while it is still, whatever torque in [−c_i, c_i] keeps it still, and it
breaks away only when that is not enough (stick–slip: a brake that holds at rest). The hybrid
system is integrated mode by mode: RK4 with the set of stuck joints and the sliding signs frozen
over a step; a step is cut where a sliding joint's velocity reaches zero (bisection on the step
length), and there the mode is chosen again. At a zero-velocity instant the mode is the one of the
inclusion M q̈ = f + λ, λ_i ∈ −c_i Sgn(q̈_i) (unique: M is positive definite), found by trying the
stuck sets from the largest: the stuck joints' holding torques within their brakes, every other
still joint moving the way its brake opposes.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from sharedctl.models.planar_arm import PlanarArmParameters

STEP = 2e-4          # s, the braked stop's RK4 step
REST = 1e-9          # rad/s: a sliding joint slower than this at a step's end has stopped


@dataclass(frozen=True)
class BrakedArm:
    """The arm plant: `parameters` (the model's), joint brakes `brake_torque` (N·m) and joint viscous
    friction `viscous` (N·m·s/rad, while braked)."""

    parameters: PlanarArmParameters
    brake_torque: tuple
    viscous: float = 0.0
    theta: tuple = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "theta", tuple(float(x) for x in self.parameters.theta()))

    # ----- the Euler–Lagrange terms on floats ---------------------------------------------------
    def terms(self, q, v):
        """(M11, M12, M22), the rest of the torque balance −C q̇ − g, for q, q̇."""
        t1, t2, t3, t4, t5 = self.theta
        c2, s2 = math.cos(q[1]), math.sin(q[1])
        c1, c12 = math.cos(q[0]), math.cos(q[0] + q[1])
        m11, m12, m22 = t1 + 2.0 * t2 * c2, t3 + t2 * c2, t3
        cv = (t2 * s2 * (-2.0 * v[0] * v[1] - v[1] * v[1]), t2 * s2 * v[0] * v[0])
        g = (t4 * c1 + t5 * c12, t5 * c12)
        return (m11, m12, m22), (-cv[0] - g[0], -cv[1] - g[1])

    def gravity(self, q) -> tuple:
        t4, t5 = self.theta[3], self.theta[4]
        c1, c12 = math.cos(q[0]), math.cos(q[0] + q[1])
        return t4 * c1 + t5 * c12, t5 * c12

    def powered_acceleration(self, q, v, tau) -> tuple:
        (m11, m12, m22), rest = self.terms(q, v)
        f0, f1 = tau[0] + rest[0], tau[1] + rest[1]
        det = m11 * m22 - m12 * m12
        return (m22 * f0 - m12 * f1) / det, (m11 * f1 - m12 * f0) / det

    # ----- powered: the drives' torque ----------------------------------------------------------
    def drive(self, q, v, tau, duration: float, steps: int = 4):
        """RK4 over `duration` with the torque τ held (brakes released): (q, q̇) as float lists."""
        q, v = [float(x) for x in q], [float(x) for x in v]
        h = duration / steps

        def f(q_, v_):
            return self.powered_acceleration(q_, v_, tau)

        for _ in range(steps):
            q, v = _rk4(f, q, v, h)
        return q, v

    # ----- disarmed: the brakes -----------------------------------------------------------------
    def braked_acceleration(self, q, v, stuck, signs) -> tuple:
        """q̈ with the joints `stuck` held and the others braked against `signs`; and the torques
        the stuck joints' brakes give."""
        (m11, m12, m22), rest = self.terms(q, v)
        c, b = self.brake_torque, self.viscous
        f = [rest[i] - b * v[i] - (0.0 if i in stuck else c[i] * signs[i]) for i in (0, 1)]
        if not stuck:
            det = m11 * m22 - m12 * m12
            return ((m22 * f[0] - m12 * f[1]) / det, (m11 * f[1] - m12 * f[0]) / det), {}
        if stuck == (0,):
            a1 = f[1] / m22
            return (0.0, a1), {0: m12 * a1 - f[0]}
        if stuck == (1,):
            a0 = f[0] / m11
            return (a0, 0.0), {1: m12 * a0 - f[1]}
        return (0.0, 0.0), {0: -f[0], 1: -f[1]}

    def mode(self, q, v) -> tuple[tuple, tuple]:
        """(stuck joints, sliding signs) at (q, q̇): joints moving slide against their velocity; of the
        still ones, the largest set whose brakes can hold them, the rest moving where they are pushed."""
        still = [i for i in (0, 1) if v[i] == 0.0]
        base = [math.copysign(1.0, v[i]) if v[i] != 0.0 else 0.0 for i in (0, 1)]
        for size in range(len(still), -1, -1):
            for stuck in itertools.combinations(still, size):
                loose = [i for i in still if i not in stuck]
                for choice in itertools.product((1.0, -1.0), repeat=len(loose)):
                    signs = list(base)
                    for i, s in zip(loose, choice):
                        signs[i] = s
                    a, held = self.braked_acceleration(q, v, stuck, signs)
                    if all(abs(held[i]) <= self.brake_torque[i] * (1.0 + 1e-12) for i in stuck) and \
                            all(a[i] * signs[i] > 0.0 for i in loose):
                        return stuck, tuple(signs)
        raise AssertionError(f"no consistent brake mode at q={q}, v={v}")

    def stop(self, q, v, max_time: float = 20.0, step: float = STEP):
        """The disarmed, braked arm from (q, q̇) until both joints are held: the positions (k, 2) at
        every step end and zero crossing, the time taken."""
        q, v = [float(x) for x in q], [float(x) for x in v]
        path, t = [list(q)], 0.0
        while t < max_time:
            stuck, signs = self.mode(q, v)
            if stuck == (0, 1):
                break

            def f(q_, v_, stuck=stuck, signs=signs):
                return self.braked_acceleration(q_, v_, stuck, signs)[0]

            h = step
            q1, v1 = _rk4(f, q, v, h)
            crossed = [i for i in (0, 1) if i not in stuck and v1[i] * signs[i] <= 0.0]
            if crossed:
                lo, hi = 0.0, h               # the first instant a sliding joint stops
                for _ in range(40):
                    mid = 0.5 * (lo + hi)
                    qm, vm = _rk4(f, q, v, mid)
                    if any(vm[i] * signs[i] <= 0.0 for i in crossed):
                        hi = mid
                    else:
                        lo = mid
                h = hi
                q1, v1 = _rk4(f, q, v, h)
                for i in (0, 1):
                    if i not in stuck and (v1[i] * signs[i] <= 0.0 or abs(v1[i]) < REST):
                        v1[i] = 0.0
            for i in stuck:
                v1[i] = 0.0
            q, v, t = q1, v1, t + h
            path.append(list(q))
        return np.array(path), t


def _rk4(f, q, v, h):
    a1 = f(q, v)
    q2 = [qi + 0.5 * h * vi for qi, vi in zip(q, v)]
    v2 = [vi + 0.5 * h * ai for vi, ai in zip(v, a1)]
    a2 = f(q2, v2)
    q3 = [qi + 0.5 * h * vi for qi, vi in zip(q, v2)]
    v3 = [vi + 0.5 * h * ai for vi, ai in zip(v, a2)]
    a3 = f(q3, v3)
    q4 = [qi + h * vi for qi, vi in zip(q, v3)]
    v4 = [vi + h * ai for vi, ai in zip(v, a3)]
    a4 = f(q4, v4)
    q_next = [qi + h / 6.0 * (vi + 2.0 * v2i + 2.0 * v3i + v4i) for qi, vi, v2i, v3i, v4i in zip(q, v, v2, v3, v4)]
    v_next = [vi + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for vi, b1, b2, b3, b4 in zip(v, a1, a2, a3, a4)]
    return q_next, v_next
