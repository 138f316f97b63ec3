"""The robust part of every law's θ̂ update: leakage onto a trust box, then projection onto the
physical box (docs/control.md §11).

Each law's own update τ (−Yᵀp/γ_θ for (12), its composite, output-feedback or (13) form) becomes

    θ̂̇ = τ − σ₀ (ϑ − P_T(ϑ)),     then θ̂ ← P_B(θ̂) after each step (laws that project),

with ϑ the estimate the law stands for (θ̂, or θ̂ + β for (13)), T = [band_lower, band_upper] the
trust box (the prior: where θ is believed to lie), B = [theta_lower, theta_upper] ⊇ T the physical
box (where θ surely lies) and P the Euclidean projection (a clip, both boxes being boxes). With
θ ∈ T, (ϑ − θ)ᵀ(ϑ − P_T(ϑ)) ≥ |ϑ − P_T(ϑ)|², so the leakage adds at most −γ σ₀ |ϑ − P_T(ϑ)|² to
the law's Lyapunov rate: nothing while the estimate is in T (the paper's law, unchanged), a
restoring term outside it. The projection bounds the estimate whatever drives it.
Unset bounds are the model's (`EulerLagrangeModel.theta_lower` …, `theta_band_lower` …; an unset face
of T moved inside a B set tighter).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

@dataclass(frozen=True)
class Adaptation:
    """σ₀ (`leakage`, 1/s; 0 turns the leakage off), the trust box T and the physical box B.
    `[gains.adaptation]` of a scenario; one for all the laws of a controller (one robot, one θ)."""

    leakage: float = 1.0
    band_lower: tuple | None = None
    band_upper: tuple | None = None
    theta_lower: tuple | None = None
    theta_upper: tuple | None = None

    def __post_init__(self):
        if isinstance(self.leakage, bool) or not isinstance(self.leakage, (int, float)) \
                or not math.isfinite(self.leakage) or self.leakage < 0.0:
            raise ValueError(f"adaptation.leakage must be a finite number >= 0, got {self.leakage!r}")
        for name in ("band_lower", "band_upper", "theta_lower", "theta_upper"):
            value = getattr(self, name)
            if value is None:
                continue
            try:
                vector = tuple(float(x) for x in value)
            except (TypeError, ValueError):
                raise ValueError(f"adaptation.{name} must be a list of numbers") from None
            if not all(math.isfinite(x) for x in vector):
                raise ValueError(f"adaptation.{name} must be finite")
            object.__setattr__(self, name, vector)

    def boxes(self, model) -> tuple[tuple, tuple, tuple, tuple]:
        """(band_lower, band_upper, theta_lower, theta_upper) as float tuples for `model`, checked
        once per model class: lower ≤ upper, T ⊆ B, n_θ entries each. `model`: a model or its class."""
        kind = model if isinstance(model, type) else type(model)
        hit = self.__dict__.get("_resolved")          # a per-step constant: kept on the (frozen) instance
        if hit is not None and hit[0] is kind:
            return hit[1]
        box_lower = self.theta_lower if self.theta_lower is not None else tuple(map(float, kind.theta_lower))
        box_upper = self.theta_upper if self.theta_upper is not None else tuple(map(float, kind.theta_upper))
        # an unset face of T is the model's, moved inside B when B is set tighter
        band_lower = self.band_lower if self.band_lower is not None else tuple(
            max(float(t), b) for t, b in zip(getattr(kind, "theta_band_lower", ()) or box_lower, box_lower))
        band_upper = self.band_upper if self.band_upper is not None else tuple(
            min(float(t), b) for t, b in zip(getattr(kind, "theta_band_upper", ()) or box_upper, box_upper))
        k = kind.n_theta
        for name, vector in (("band_lower", band_lower), ("band_upper", band_upper),
                             ("theta_lower", box_lower), ("theta_upper", box_upper)):
            if vector and len(vector) != k:
                raise ValueError(f"adaptation.{name} must have {k} entries (the model's θ), has {len(vector)}")
        if box_lower and any(lo > hi for lo, hi in zip(box_lower, box_upper)):
            raise ValueError("adaptation: theta_lower must not exceed theta_upper")
        if any(lo > hi for lo, hi in zip(band_lower, band_upper)):
            raise ValueError("adaptation: band_lower must not exceed band_upper")
        if box_lower and not all(bl <= lo and hi <= bu for lo, hi, bl, bu in
                                 zip(band_lower, band_upper, box_lower, box_upper)):
            raise ValueError("adaptation: the trust box [band_lower, band_upper] must lie inside "
                             "[theta_lower, theta_upper]")
        resolved = (band_lower, band_upper, box_lower, box_upper)
        self.__dict__["_resolved"] = (kind, resolved)
        return resolved

    def box(self, model) -> tuple[tuple, tuple]:
        """B = (theta_lower, theta_upper) for `model` (empty tuples: no box)."""
        return self.boxes(model)[2:]

    def leak(self, model, estimate: list) -> list | None:
        """σ₀ (ϑ − P_T(ϑ)) on Python floats, or None when it is zero (ϑ in T, or σ₀ = 0)."""
        sigma = self.leakage
        if not sigma:
            return None
        lower, upper = self.boxes(model)[:2]
        out = None
        for i, (e, lo, hi) in enumerate(zip(estimate, lower, upper)):
            if e > hi or e < lo:
                if out is None:
                    out = [0.0] * len(estimate)
                out[i] = sigma * (e - hi) if e > hi else sigma * (e - lo)
        return out


def leaked(rate: list, leak: list | None) -> list:
    """A law's θ̂̇ (floats) less the leakage (the same floats when there is none)."""
    return rate if leak is None else [r - s for r, s in zip(rate, leak)]


def band_excess(adaptation: Adaptation, model, estimate: np.ndarray) -> np.ndarray:
    """ϑ − P_T(ϑ) (for analysis and tests)."""
    lower, upper = adaptation.boxes(model)[:2]
    estimate = np.asarray(estimate, float)
    return estimate - np.clip(estimate, lower, upper) if lower else np.zeros_like(estimate)
