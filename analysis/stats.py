"""The paper's statistics: R_T, improvement over the baseline, t-tests, correlations.

Every function takes the episode table (see `episodes.py`) and returns a DataFrame that
can be written as CSV as it is. The definitions follow the paper's "Results":

- `R_T` of an agent is the sum of its collected reward over the N episodes (Eq. 3).
- `R_T` of a method is the sum over episodes of the method's average curve (the black,
  blue and red lines of Figure 5); with equal N it equals the mean of its agents' R_T.
- The improvement of a method is `(R_T - R_T_baseline) / R_T_baseline * 100` where the
  baseline's R_T is positive; against a reference that is not, a percentage says nothing
  (+405 % of a negative score), so reports give the difference in points instead.
- Table 2 compares two methods' average curves as two samples of N values each, with
  the independent two-sample Student t-test (equal variances): t = 7.6829 with
  p = 6.3947e-14 is what N = 300 per sample (598 degrees of freedom) gives, and not what
  10 agents per method would. We reproduce that test and add the one on per-agent R_T.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats

from analysis.episodes import (
    OUTCOME_COLUMNS,
    EpisodeTableError,
    agents_of,
    method_name,
    order_methods,
    reward_curves,
    validate_episodes,
)

EPISODE_MEANS = "episode_means"
"""t-test sample: a method's average collected reward per episode (N values), as in Table 2."""

AGENT_TOTALS = "agent_totals"
"""t-test sample: the R_T of each of a method's agents (one value per agent)."""


def _check_baseline(table: pd.DataFrame, baseline: str | None) -> None:
    if baseline is not None and baseline not in set(table["method"]):
        present = ", ".join(order_methods(table["method"]))
        raise EpisodeTableError(
            f"baseline method {baseline!r} has no sessions (methods present: {present}). "
            "Pass one of those as baseline, or baseline=None to skip the improvement"
        )


def improvement_pct(total: float, baseline_total: float) -> float:
    """How much more reward than the baseline, in percent of the baseline's R_T; NaN where
    that is not positive (a short run's negative R_T): a percentage of it misleads, and
    `analysis.markdown.versus` gives the difference in points instead."""
    if not baseline_total > 0:
        return float("nan")
    return (total - baseline_total) / baseline_total * 100.0


def method_curves(episodes: pd.DataFrame) -> pd.DataFrame:
    """Per method and episode: mean and sample std (ddof=1) of collected reward across agents.

    Columns: method, episode, mean, std, agents. These are Figure 5's lines and bands.
    """
    table = validate_episodes(episodes)
    grouped = table.groupby(["method", "episode"], sort=False)["collected_reward"]
    curves = grouped.agg(mean="mean", std="std", agents="count").reset_index()
    return curves


def agent_totals(episodes: pd.DataFrame, *, baseline: str | None = "autonomous") -> pd.DataFrame:
    """R_T per agent, with its improvement over the baseline method's R_T.

    Columns: session_id, label, method, [seed], episodes, R_T, mean_reward (R_T / N),
    improvement_pct (NaN without a baseline, or where its R_T is not positive) and
    difference (R_T minus the baseline's, in points; NaN without a baseline).
    """
    table = validate_episodes(episodes)
    _check_baseline(table, baseline)
    agents = agents_of(table)
    grouped = table.groupby("session_id", sort=False)["collected_reward"]
    agents["episodes"] = agents["session_id"].map(grouped.count()).astype(int)
    agents["R_T"] = agents["session_id"].map(grouped.sum())
    agents["mean_reward"] = agents["R_T"] / agents["episodes"]
    if baseline is None:
        agents["improvement_pct"] = np.nan
        agents["difference"] = np.nan
    else:
        base = _method_total(table, baseline)
        agents["improvement_pct"] = [improvement_pct(r, base) for r in agents["R_T"]]
        agents["difference"] = agents["R_T"] - base
    return agents


def _method_total(table: pd.DataFrame, method: str) -> float:
    rows = table[table["method"] == method]
    return float(rows.groupby("episode")["collected_reward"].mean().sum())


def method_totals(episodes: pd.DataFrame, *, baseline: str | None = "autonomous") -> pd.DataFrame:
    """R_T per method (the paper's definition) with the spread of its agents' R_T.

    Columns: method, name, agents, episodes, R_T, R_T_std (sample std of the agents' R_T),
    R_T_min, R_T_max, improvement_pct, difference (as `agent_totals`), and the mean per
    episode of every outcome column present (`steps`, `placed_correct`, `misplaced`, `lost`);
    with a `success` column, `success_rate`: the share of the method's episodes that
    succeeded (the task's `is_success`).
    """
    table = validate_episodes(episodes)
    _check_baseline(table, baseline)
    per_agent = agent_totals(table, baseline=None)
    base = None if baseline is None else _method_total(table, baseline)
    rows = []
    for method in order_methods(table["method"], baseline):
        totals = per_agent.loc[per_agent["method"] == method, "R_T"]
        total = _method_total(table, method)
        row: dict[str, object] = {
            "method": method,
            "name": method_name(method),
            "agents": len(totals),
            "episodes": int(per_agent.loc[per_agent["method"] == method, "episodes"].iloc[0]),
            "R_T": total,
            "R_T_std": float(totals.std(ddof=1)) if len(totals) > 1 else float("nan"),
            "R_T_min": float(totals.min()),
            "R_T_max": float(totals.max()),
            "improvement_pct": float("nan") if base is None else improvement_pct(total, base),
            "difference": float("nan") if base is None else total - base,
        }
        for column in OUTCOME_COLUMNS:
            if column in table:
                values = pd.to_numeric(table.loc[table["method"] == method, column])
                row[f"{column}_per_episode"] = float(values.mean())
        if "success" in table:  # the share of its episodes the task counts as a success
            row["success_rate"] = float(table.loc[table["method"] == method, "success"].mean())
        rows.append(row)
    return pd.DataFrame(rows)


def student_t_test(a: np.ndarray, b: np.ndarray, *, equal_var: bool = True) -> tuple[float, float]:
    """Two-sided independent two-sample t-test of a against b: (t, p); NaN if undefined.

    t > 0 means sample a has the larger mean. Undefined when a sample has fewer than two
    values, or when both samples are constant.
    """
    if len(a) < 2 or len(b) < 2:
        return float("nan"), float("nan")
    if np.ptp(a) == 0 and np.ptp(b) == 0:  # every value equal in each (as the power's
        return float("nan"), float("nan")  # welch_rejects: scipy gives t = ±inf, p = 0)
    with warnings.catch_warnings(), np.errstate(divide="ignore", invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)  # a constant sample is legitimate
        result = stats.ttest_ind(a, b, equal_var=equal_var)
    return float(result.statistic), float(result.pvalue)


def method_pairs(methods: Iterable[str], baseline: str | None) -> list[tuple[str, str]]:
    """The pairs t-tested: (method, baseline) for every other method, then the others."""
    order = order_methods(methods, baseline)
    if baseline not in order:
        return list(combinations(order, 2))
    others = [m for m in order if m != baseline]
    return [(m, baseline) for m in others] + list(combinations(others, 2))


def t_tests(
    episodes: pd.DataFrame, *, baseline: str | None = "autonomous", equal_var: bool = True
) -> pd.DataFrame:
    """Student's t-tests between every pair of methods, on two kinds of sample.

    Pairs (method_a, method_b): every method against the baseline (the baseline is
    method_b), then the other methods among themselves in display order (`method_pairs`).
    `sample = "episode_means"` compares the two average curves, N values each (the
    paper's Table 2); `sample = "agent_totals"` compares the agents' R_T, one value per
    agent. Columns: method_a, method_b, sample, n_a, n_b, mean_a, mean_b, t, p, df, test,
    and Welch's test (unequal variances) beside it: t_welch, p_welch, df_welch; with a
    handful of agents whose spreads differ (advised agents vary less), Welch's is the
    safer reading.
    t is scipy's `ttest_ind(a, b)`: t > 0 means method_a's sample has the larger mean,
    so against the baseline t > 0 means more reward than the baseline. The paper
    prints |t|.
    """
    table = validate_episodes(episodes)
    _check_baseline(table, baseline)
    curves = table.groupby(["method", "episode"], sort=False)["collected_reward"].mean()
    per_agent = agent_totals(table, baseline=None)
    samples = {
        EPISODE_MEANS: {m: curves.loc[m].to_numpy() for m in set(table["method"])},
        AGENT_TOTALS: {
            m: per_agent.loc[per_agent["method"] == m, "R_T"].to_numpy()
            for m in set(table["method"])
        },
    }
    name = "Student's t-test (two-sided, equal variances)" if equal_var else "Welch's t-test"
    rows = []
    for method_a, method_b in method_pairs(table["method"], baseline):
        for sample, by_method in samples.items():
            a, b = by_method[method_a], by_method[method_b]
            t, p = student_t_test(a, b, equal_var=equal_var)
            t_welch, p_welch = student_t_test(a, b, equal_var=False)
            dof_welch = welch_dof(a, b)
            dof = len(a) + len(b) - 2 if equal_var else dof_welch
            rows.append(
                {
                    "method_a": method_a,
                    "method_b": method_b,
                    "sample": sample,
                    "n_a": len(a),
                    "n_b": len(b),
                    "mean_a": float(a.mean()),
                    "mean_b": float(b.mean()),
                    "t": t,
                    "p": p,
                    "df": dof,
                    "test": name,
                    "t_welch": t_welch,
                    "p_welch": p_welch,
                    "df_welch": dof_welch,
                }
            )
    columns = ["method_a", "method_b", "sample", "n_a", "n_b", "mean_a", "mean_b"]
    welch = ["t_welch", "p_welch", "df_welch"]
    return pd.DataFrame(rows, columns=[*columns, "t", "p", "df", "test", *welch])


def welch_dof(a: np.ndarray, b: np.ndarray) -> float:
    """Welch-Satterthwaite degrees of freedom; NaN when undefined (as the test is)."""
    if len(a) < 2 or len(b) < 2:
        return float("nan")
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    if va + vb == 0:
        return float("nan")
    return float((va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1)))


def correlation_matrix(episodes: pd.DataFrame, labels: list[str] | None = None) -> pd.DataFrame:
    """Pearson's r between agents' reward curves (Figure 7), indexed by label both ways.

    `labels` picks and orders the agents (all, in table order, by default). An agent whose
    curve is constant has no correlation: its row and column are NaN.
    """
    curves = reward_curves(episodes)
    if labels is not None:
        unknown = [label for label in labels if label not in curves.columns]
        if unknown:
            raise EpisodeTableError(
                f"no agent labelled {', '.join(map(repr, unknown))}. "
                f"Pick from: {', '.join(curves.columns)}"
            )
        curves = curves[list(labels)]
    values = curves.to_numpy(dtype=float)
    centered = values - values.mean(axis=0)
    norms = np.sqrt((centered**2).sum(axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (centered.T @ centered) / np.outer(norms, norms)
    r = np.clip(r, -1.0, 1.0)
    r[:, norms == 0] = np.nan
    r[norms == 0, :] = np.nan
    matrix = pd.DataFrame(r, index=curves.columns, columns=curves.columns)
    matrix.index.name = "label"
    matrix.columns.name = None
    return matrix


def method_correlations(episodes: pd.DataFrame, matrix: pd.DataFrame) -> pd.DataFrame:
    """Mean Pearson's r between agents of two methods (an agent with itself excluded).

    Summarises Figure 7 in one number per pair of methods: are advised agents more alike
    than autonomous ones? Columns: method_a, method_b, pairs, mean_r.
    """
    agents = agents_of(validate_episodes(episodes)).set_index("label")
    methods = agents.loc[list(matrix.index), "method"]
    rows = []
    order = order_methods(methods)
    for i, method_a in enumerate(order):
        for method_b in order[i:]:
            block = matrix.loc[methods == method_a, methods == method_b].to_numpy()
            if method_a == method_b:
                block = block[~np.eye(len(block), dtype=bool)]
            values = block[np.isfinite(block)]
            rows.append(
                {
                    "method_a": method_a,
                    "method_b": method_b,
                    "pairs": int(values.size),
                    "mean_r": float(values.mean()) if values.size else float("nan"),
                }
            )
    return pd.DataFrame(rows)
