"""Statistics that hold up with 4-10 agents per method: bootstrap intervals and the IQM.

A p-value says little about how large a difference is, and the paper's Table 2 test
treats successive episodes of one learning curve as independent. Following Agarwal et al.
("Deep RL at the edge of the statistical precipice", NeurIPS 2021, the `rliable`
library), we report for each method the mean of its agents' R_T and their interquartile
mean (IQM: the mean of the middle 50 %, robust to one run that failed or took off) with
percentile bootstrap confidence intervals over agents, and the same for the difference
between two methods (agents of each method resampled independently). scipy does the
resampling (`scipy.stats.bootstrap`, `scipy.stats.trim_mean`). The percentile method,
not BCa: with a handful of agents BCa's acceleration estimate is itself unstable, and
the percentile interval is what `rliable` reports. With few agents every bootstrap
interval is too narrow (it cannot see values the sample does not hold): read it as a
description of the runs, not a guarantee.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial

import numpy as np
import pandas as pd
from scipy import stats

from analysis.episodes import method_name, order_methods, validate_episodes
from analysis.stats import agent_totals, method_pairs

CONFIDENCE = 0.95
"""Confidence level of every interval."""
RESAMPLES = 10_000
"""Bootstrap resamples per interval."""
SEED = 0
"""Seed of the bootstrap's generator: the same table gives the same intervals."""

Statistic = Callable[..., np.ndarray | float]
METHOD_COLUMNS = [
    *("method", "name", "agents", "R_T_mean", "R_T_low", "R_T_high"),
    *("IQM", "IQM_low", "IQM_high", "confidence"),
]
DIFFERENCE_COLUMNS = [
    *("method_a", "method_b", "n_a", "n_b", "difference", "low", "high"),
    *("IQM_difference", "IQM_low", "IQM_high", "confidence"),
]


def iqm(values: Sequence[float] | np.ndarray, axis: int = -1) -> np.ndarray | float:
    """Interquartile mean: the mean after cutting 25 % of the values from each end."""
    return stats.trim_mean(np.asarray(values, dtype=float), 0.25, axis=axis)


def _mean(values: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(values, axis=axis)


def bootstrap_interval(
    samples: Sequence[np.ndarray],
    statistic: Statistic,
    *,
    confidence: float = CONFIDENCE,
    n_resamples: int = RESAMPLES,
    seed: int = SEED,
) -> tuple[float, float]:
    """Percentile bootstrap interval of `statistic(*samples, axis=...)`, each sample
    resampled on its own; NaN when a sample has fewer than two values, and the value
    itself when every sample is constant (no resample can differ)."""
    samples = [np.asarray(s, dtype=float) for s in samples]
    if any(len(s) < 2 for s in samples):
        return float("nan"), float("nan")
    if all(np.ptp(s) == 0 for s in samples):
        value = float(statistic(*samples, axis=-1))
        return value, value
    result = stats.bootstrap(
        samples,
        statistic,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method="percentile",
        vectorized=True,
        paired=False,
        rng=np.random.default_rng(seed),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def _difference(statistic: Statistic) -> Statistic:
    def difference(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray | float:
        return statistic(a, axis=axis) - statistic(b, axis=axis)

    return difference


def _totals(episodes: pd.DataFrame) -> dict[str, np.ndarray]:
    per_agent = agent_totals(episodes, baseline=None)
    return {m: g["R_T"].to_numpy(dtype=float) for m, g in per_agent.groupby("method")}


def method_intervals(
    episodes: pd.DataFrame,
    *,
    baseline: str | None = "autonomous",
    confidence: float = CONFIDENCE,
    n_resamples: int = RESAMPLES,
    seed: int = SEED,
) -> pd.DataFrame:
    """Per method: the mean and IQM of its agents' R_T, each with a bootstrap interval.

    Columns: method, name, agents, R_T_mean, R_T_low, R_T_high, IQM, IQM_low, IQM_high,
    confidence. `R_T_mean` equals the method's R_T when its agents ran the same number of
    episodes (`validate_episodes` makes it so).
    """
    table = validate_episodes(episodes)
    totals = _totals(table)
    interval = partial(
        bootstrap_interval, confidence=confidence, n_resamples=n_resamples, seed=seed
    )
    rows = []
    for method in order_methods(table["method"], baseline):
        values = totals[method]
        low, high = interval([values], _mean)
        iqm_low, iqm_high = interval([values], iqm)
        rows.append(
            {
                "method": method,
                "name": method_name(method),
                "agents": len(values),
                "R_T_mean": float(values.mean()),
                "R_T_low": low,
                "R_T_high": high,
                "IQM": float(iqm(values)),
                "IQM_low": iqm_low,
                "IQM_high": iqm_high,
                "confidence": confidence,
            }
        )
    return pd.DataFrame(rows, columns=METHOD_COLUMNS)


def difference_intervals(
    episodes: pd.DataFrame,
    *,
    baseline: str | None = "autonomous",
    confidence: float = CONFIDENCE,
    n_resamples: int = RESAMPLES,
    seed: int = SEED,
) -> pd.DataFrame:
    """For every pair the t-tests compare (`stats.method_pairs`): method_a's agents' mean
    R_T minus method_b's, and the same for the IQM, with bootstrap intervals.

    Columns: method_a, method_b, n_a, n_b, difference, low, high, IQM_difference,
    IQM_low, IQM_high, confidence. An interval that excludes 0 says the runs differ in
    that direction at this confidence.
    """
    table = validate_episodes(episodes)
    totals = _totals(table)
    interval = partial(
        bootstrap_interval, confidence=confidence, n_resamples=n_resamples, seed=seed
    )
    rows = []
    for method_a, method_b in method_pairs(table["method"], baseline):
        a, b = totals[method_a], totals[method_b]
        low, high = interval([a, b], _difference(_mean))
        iqm_low, iqm_high = interval([a, b], _difference(iqm))
        rows.append(
            {
                "method_a": method_a,
                "method_b": method_b,
                "n_a": len(a),
                "n_b": len(b),
                "difference": float(a.mean() - b.mean()),
                "low": low,
                "high": high,
                "IQM_difference": float(iqm(a) - iqm(b)),
                "IQM_low": iqm_low,
                "IQM_high": iqm_high,
                "confidence": confidence,
            }
        )
    return pd.DataFrame(rows, columns=DIFFERENCE_COLUMNS)
