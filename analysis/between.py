"""Tests between two groups of participants, the participant as the unit: Welch's t for
continuous measures, Mann-Whitney's U for ordinal ones (Likert items, NASA-TLX
subscales), Fisher's exact test for rates; each with an effect size and its interval at
the study's confidence, and Holm's correction within a family of tests.

A test needs two participants in each group and some variation among their values;
without them the row says "no test" and why, rather than a p-value that means nothing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

WELCH = "Welch's t"
MANN_WHITNEY = "Mann-Whitney U"
FISHER = "Fisher's exact"


@dataclass(frozen=True)
class Tested:
    """One test between groups a and b."""

    test: str
    """`WELCH`, `MANN_WHITNEY` or `FISHER`."""
    n_a: int
    n_b: int
    statistic: float
    """t, U (of group a) or the odds ratio; NaN without a test."""
    p: float
    """Two-sided; NaN without a test."""
    effect: str
    """What `estimate` measures: difference in means (a - b), ratio of geometric means
    (a / b), rank-biserial correlation (> 0: a tends higher), difference in proportions."""
    estimate: float
    low: float
    high: float
    """The effect's interval at 1 - alpha."""
    no_test: str = ""
    """Why there is no test (fewer than two participants in a group, no variation); empty
    where there is one."""


def _no_test(test: str, effect: str, n_a: int, n_b: int, why: str) -> Tested:
    nan = float("nan")
    return Tested(test, n_a, n_b, nan, nan, effect, nan, nan, nan, why)


def _too_few(n_a: int, n_b: int) -> str:
    if min(n_a, n_b) < 2:
        return "fewer than two participants in a group"
    return ""


def welch(a: Sequence[float], b: Sequence[float], alpha: float, log: bool = False) -> Tested:
    """Welch's t-test of a against b, with the difference in means and its Welch interval;
    `log`: on the logarithm of the values (decision times), the effect then the ratio of
    the geometric means."""
    x = np.log(np.asarray(a, float)) if log else np.asarray(a, float)
    y = np.log(np.asarray(b, float)) if log else np.asarray(b, float)
    effect = "ratio of geometric means (a / b)" if log else "difference in means (a - b)"
    why = _too_few(len(x), len(y))
    if not why and np.var(np.concatenate([x, y])) == 0:
        why = "no variation: every participant has the same value"
    if not why and np.var(x, ddof=1) == 0 and np.var(y, ddof=1) == 0:
        why = "no variation within either group"
    if why:
        return _no_test(WELCH, effect, len(x), len(y), why)
    va, vb = np.var(x, ddof=1) / len(x), np.var(y, ddof=1) / len(y)
    se = math.sqrt(va + vb)
    df = (va + vb) ** 2 / (va**2 / (len(x) - 1) + vb**2 / (len(y) - 1))
    diff = float(x.mean() - y.mean())
    t = diff / se
    p = float(2 * stats.t.sf(abs(t), df))
    half = float(stats.t.ppf(1 - alpha / 2, df)) * se
    low, high = diff - half, diff + half
    if log:
        diff, low, high = math.exp(diff), math.exp(low), math.exp(high)
    return Tested(WELCH, len(x), len(y), t, p, effect, diff, low, high)


def mann_whitney(a: Sequence[float], b: Sequence[float], alpha: float) -> Tested:
    """Mann-Whitney's U (two-sided) with the rank-biserial correlation 2U/(n_a n_b) - 1 and
    its interval from Hanley and McNeil's standard error of the AUC (U / (n_a n_b)), clipped
    to [-1, 1]."""
    x, y = np.asarray(a, float), np.asarray(b, float)
    effect = "rank-biserial correlation (> 0: a higher)"
    why = _too_few(len(x), len(y))
    if not why and np.unique(np.concatenate([x, y])).size == 1:
        why = "no variation: every participant gave the same answer"
    if why:
        return _no_test(MANN_WHITNEY, effect, len(x), len(y), why)
    result = stats.mannwhitneyu(x, y, alternative="two-sided")
    u = float(result.statistic)
    pairs = len(x) * len(y)
    auc = u / pairs
    # At U = 0 or U = n_a n_b the standard error is 0: half a pair keeps it from collapsing.
    edge = min(max(auc, 0.5 / pairs), 1 - 0.5 / pairs)
    q1, q2 = edge / (2 - edge), 2 * edge**2 / (1 + edge)
    var = (
        edge * (1 - edge) + (len(x) - 1) * (q1 - edge**2) + (len(y) - 1) * (q2 - edge**2)
    ) / pairs
    half = float(stats.norm.ppf(1 - alpha / 2)) * math.sqrt(max(var, 0.0))
    low, high = max(0.0, auc - half), min(1.0, auc + half)
    return Tested(
        MANN_WHITNEY, len(x), len(y), u, float(result.pvalue), effect,
        2 * auc - 1, 2 * low - 1, 2 * high - 1,
    )  # fmt: skip


def wilson(successes: int, n: int, alpha: float) -> tuple[float, float]:
    """Wilson's score interval of a proportion."""
    z = float(stats.norm.ppf(1 - alpha / 2))
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return centre - half, centre + half


def fisher(successes_a: int, n_a: int, successes_b: int, n_b: int, alpha: float) -> Tested:
    """Fisher's exact test (two-sided) of two rates, with the difference in proportions
    (a - b) and Newcombe's hybrid score interval (his method 10, from Wilson's)."""
    effect = "difference in proportions (a - b)"
    why = _too_few(n_a, n_b)
    if not why and successes_a + successes_b in (0, n_a + n_b):
        why = "no variation: the rate is the same for every participant"
    if why:
        return _no_test(FISHER, effect, n_a, n_b, why)
    table = [[successes_a, n_a - successes_a], [successes_b, n_b - successes_b]]
    result = stats.fisher_exact(table, alternative="two-sided")
    pa, pb = successes_a / n_a, successes_b / n_b
    la, ua = wilson(successes_a, n_a, alpha)
    lb, ub = wilson(successes_b, n_b, alpha)
    diff = pa - pb
    low = diff - math.sqrt((pa - la) ** 2 + (ub - pb) ** 2)
    high = diff + math.sqrt((ua - pa) ** 2 + (pb - lb) ** 2)
    return Tested(
        FISHER, n_a, n_b, float(result.statistic), float(result.pvalue), effect, diff, low, high
    )


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values, in the order given; NaN (no test) stays NaN and
    does not count among the tests."""
    tested = sorted((p, i) for i, p in enumerate(p_values) if not math.isnan(p))
    adjusted = [float("nan")] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(tested):
        running = max(running, min(1.0, (len(tested) - rank) * p))
        adjusted[i] = running
    return adjusted
