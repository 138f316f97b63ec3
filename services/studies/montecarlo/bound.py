"""The one-sided 95 % Clopper–Pearson upper bound on a binomial probability.

After k events (violations) in n independent trials (runs), the exact upper bound on the probability p
of an event at confidence 1 − α = 0.95 is the p at which seeing k events or fewer becomes a 5 % tail:

    P(Binomial(n, p) ≤ k) = α,   i.e.   p_upper = B⁻¹(1 − α; k + 1, n − k),

B⁻¹ being the quantile of the Beta distribution (Clopper and Pearson, 1934). Read it as: "had the true
probability been above p_upper, a run of n trials would have shown k events or fewer less than 5 % of
the time". With k = 0 it is 1 − α^(1/n) ≈ −ln(0.05)/n ≈ 3/n: the "rule of three" (no violation in 3000
runs bounds the violation probability by 0.1 % at 95 %). With k = n nothing bounds p below 1.
"""
from __future__ import annotations

from scipy.stats import beta

CONFIDENCE = 0.95


def upper_95(k: int, n: int) -> float:
    """The one-sided 95 % Clopper–Pearson upper bound on p after k events in n trials:
    `beta.ppf(0.95, k + 1, n - k)`, 1.0 when k == n. ValueError unless n ≥ 1 and 0 ≤ k ≤ n."""
    if n < 1:
        raise ValueError(f"upper_95: n must be at least 1 trial, got n={n}")
    if not 0 <= k <= n:
        raise ValueError(f"upper_95: k must lie in 0..n={n}, got k={k}")
    if k == n:
        return 1.0
    return float(beta.ppf(CONFIDENCE, k + 1, n - k))
