"""Every table of the analysis computed at once, for the report and the dashboard."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from analysis.episodes import order_methods, validate_episodes
from analysis.figures import epsilon_reaches
from analysis.intervals import difference_intervals, method_intervals
from analysis.paper import paper_comparison
from analysis.stats import (
    agent_totals,
    correlation_matrix,
    method_correlations,
    method_curves,
    method_totals,
    t_tests,
)


@dataclass(frozen=True)
class Analysis:
    """The statistics of one set of sessions; each table is ready to write as CSV."""

    episodes: pd.DataFrame
    """The validated episode table (labels filled in, sorted, cut to `n_episodes`)."""
    baseline: str | None
    """The method the improvement is measured against; None: no improvement computed."""
    methods: pd.DataFrame
    """R_T per method, its spread across agents, improvement (`stats.method_totals`)."""
    agents: pd.DataFrame
    """R_T per agent and its improvement over the baseline method (`stats.agent_totals`)."""
    curves: pd.DataFrame
    """Mean and std of collected reward per method and episode (`stats.method_curves`)."""
    t_tests: pd.DataFrame
    """Student's t-tests for every pair of methods, on both samples (`stats.t_tests`)."""
    correlation: pd.DataFrame
    """Pearson's r between every pair of agents' reward curves (`stats.correlation_matrix`)."""
    method_correlations: pd.DataFrame
    """Mean r between agents of two methods (`stats.method_correlations`)."""
    paper: pd.DataFrame
    """The paper's published numbers beside ours (`paper.paper_comparison`)."""
    epsilon_reached: pd.Series | None
    """First episode where a method's mean epsilon is at most 1 %; None without epsilon."""
    intervals: pd.DataFrame | None = None
    """Mean and IQM of agents' R_T per method with bootstrap intervals (`intervals`)."""
    differences: pd.DataFrame | None = None
    """Differences of those between methods, with bootstrap intervals (`intervals`)."""

    @property
    def method_order(self) -> list[str]:
        """Methods in display order, baseline first."""
        return order_methods(self.episodes["method"], self.baseline)

    @property
    def n_episodes(self) -> int:
        """Episodes per agent (equal for all after validation)."""
        return int(self.episodes["episode"].max())


def analyze(
    episodes: pd.DataFrame,
    *,
    baseline: str | None = "autonomous",
    n_episodes: int | None = None,
    equal_var: bool = True,
) -> Analysis:
    """Validate the episode table and compute every statistic of the paper's analysis.

    `n_episodes` keeps the first N episodes of every agent (see `validate_episodes`);
    `equal_var=False` switches the t-tests to Welch's test.
    """
    table = validate_episodes(episodes, n_episodes=n_episodes)
    methods = method_totals(table, baseline=baseline)
    tests = t_tests(table, baseline=baseline, equal_var=equal_var)
    correlation = correlation_matrix(table)
    return Analysis(
        episodes=table,
        baseline=baseline,
        methods=methods,
        agents=agent_totals(table, baseline=baseline),
        curves=method_curves(table),
        t_tests=tests,
        correlation=correlation,
        method_correlations=method_correlations(table, correlation),
        paper=paper_comparison(methods, tests, baseline=baseline),
        epsilon_reached=epsilon_reaches(table) if "epsilon" in table else None,
        intervals=method_intervals(table, baseline=baseline),
        differences=difference_intervals(table, baseline=baseline),
    )
