"""Equivalence by two one-sided tests (TOST), paired: is a difference inside a margin?

A significance test cannot show that two ways of running the same agents agree (a large
p-value is only the absence of evidence); TOST can. With the paired differences d_i of n
pairs and a margin delta, it rejects both "mean d <= -delta" and "mean d >= +delta" at
level alpha, which is the same as the (1 - 2 alpha) confidence interval of mean d lying
inside (-delta, +delta) (Schuirmann 1987). The plan (docs/results/plan.md) uses it with a
margin of 3 % of the reference arm's mean R_T: populations against agents alone, float32
against bfloat16.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class Equivalence:
    """The result of `paired_tost`."""

    n: int
    mean_difference: float
    """Mean of (b - a) over the pairs."""
    margin: float
    """The absolute margin: +-margin around 0."""
    interval: tuple[float, float]
    """The (1 - 2 alpha) confidence interval of the mean difference."""
    p_value: float
    """The larger of the two one-sided p-values: equivalence is shown when it is < alpha."""
    alpha: float
    identical: bool
    """Every pair agrees exactly (the differences are all 0)."""

    @property
    def equivalent(self) -> bool:
        return self.p_value < self.alpha

    def sentence(self, unit: str = "") -> str:
        low, high = self.interval
        verdict = "equivalent" if self.equivalent else "not shown equivalent"
        same = "; every pair identical" if self.identical else ""
        return (
            f"{verdict} within +-{self.margin:.4g}{unit} (n = {self.n} pairs, mean difference "
            f"{self.mean_difference:+.4g}{unit}, {100 * (1 - 2 * self.alpha):.0f} % interval "
            f"[{low:+.4g}, {high:+.4g}], TOST p = {self.p_value:.3g}{same})"
        )


def relative_margin(reference: Sequence[float], fraction: float) -> float:
    """`fraction` of the reference arm's mean, as an absolute margin (R_T can be negative)."""
    values = np.asarray(reference, dtype=float)
    if values.size == 0 or not np.isfinite(values).all():
        raise ValueError("the reference arm needs finite values")
    if not fraction > 0:
        raise ValueError(f"the margin's fraction must be > 0, got {fraction}")
    return float(abs(values.mean()) * fraction)


def paired_tost(
    a: Sequence[float], b: Sequence[float], margin: float, *, alpha: float = 0.05
) -> Equivalence:
    """Two one-sided paired t-tests of mean(b - a) against -margin and +margin.

    Pairs that agree exactly have a standard error of 0: then the interval is the point
    mean difference, and equivalence holds exactly when it lies strictly inside the margin
    (p = 0), else not (p = 1)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"paired samples need the same length, got {x.shape} and {y.shape}")
    if x.size < 2:
        raise ValueError("a paired test needs at least 2 pairs")
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise ValueError("the samples must be finite")
    if not (margin > 0 and np.isfinite(margin)):
        raise ValueError(f"the margin must be a positive number, got {margin}")
    if not 0 < alpha < 0.5:
        raise ValueError(f"alpha must be in (0, 0.5), got {alpha}")
    d = y - x
    n = int(d.size)
    mean = float(d.mean())
    se = float(d.std(ddof=1) / np.sqrt(n))
    identical = bool((d == 0).all())
    if se == 0:
        inside = -margin < mean < margin
        return Equivalence(n, mean, margin, (mean, mean), 0.0 if inside else 1.0, alpha, identical)
    dof = n - 1
    p_lower = float(stats.t.sf((mean + margin) / se, dof))  # H0: mean <= -margin
    p_upper = float(stats.t.cdf((mean - margin) / se, dof))  # H0: mean >= +margin
    half = float(stats.t.ppf(1 - alpha, dof) * se)
    return Equivalence(
        n, mean, margin, (mean - half, mean + half), max(p_lower, p_upper), alpha, identical
    )
