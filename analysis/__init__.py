"""The paper's analysis over an episode table: R_T, t-tests, correlations, figures, report.

Pure functions over pandas DataFrames; nothing here reads the database. The table is one
row per (session, episode) — see `analysis.episodes.CONTRACT` — and
`write_report(episodes_df, out_dir)` is the entry point for the CLI and the dashboard.

Importing this package loads nothing but itself: a name is imported from its module when it
is first used, so a part that needs one module (the export's audit settings, the episode
table's contract) does not bring matplotlib and scipy with it.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

_MODULE_OF = {
    "CONTRACT": "episodes",
    "METHOD_NAMES": "episodes",
    "EpisodeTableError": "episodes",
    "method_name": "episodes",
    "order_methods": "episodes",
    "reward_curves": "episodes",
    "validate_episodes": "episodes",
    "plot_correlation": "figures",
    "plot_cumulative_reward": "figures",
    "plot_epsilon": "figures",
    "plot_individual_agents": "figures",
    "plot_method_curves": "figures",
    "save_figure": "figures",
    "bootstrap_interval": "intervals",
    "difference_intervals": "intervals",
    "iqm": "intervals",
    "method_intervals": "intervals",
    "paper_comparison": "paper",
    "ReportResult": "report",
    "write_report": "report",
    "agent_totals": "stats",
    "correlation_matrix": "stats",
    "improvement_pct": "stats",
    "method_correlations": "stats",
    "method_curves": "stats",
    "method_totals": "stats",
    "student_t_test": "stats",
    "t_tests": "stats",
    "Analysis": "summary",
    "analyze": "summary",
    "demo_episodes": "demo_curves",
}
"""Where each public name lives (its module in this package)."""

__all__ = [
    "CONTRACT",
    "METHOD_NAMES",
    "Analysis",
    "EpisodeTableError",
    "ReportResult",
    "agent_totals",
    "analyze",
    "bootstrap_interval",
    "correlation_matrix",
    "demo_episodes",
    "difference_intervals",
    "improvement_pct",
    "iqm",
    "method_correlations",
    "method_curves",
    "method_intervals",
    "method_name",
    "method_totals",
    "order_methods",
    "paper_comparison",
    "plot_correlation",
    "plot_cumulative_reward",
    "plot_epsilon",
    "plot_individual_agents",
    "plot_method_curves",
    "reward_curves",
    "save_figure",
    "student_t_test",
    "t_tests",
    "validate_episodes",
    "write_report",
]

if TYPE_CHECKING:
    from analysis.demo_curves import demo_episodes
    from analysis.episodes import (
        CONTRACT,
        METHOD_NAMES,
        EpisodeTableError,
        method_name,
        order_methods,
        reward_curves,
        validate_episodes,
    )
    from analysis.figures import (
        plot_correlation,
        plot_cumulative_reward,
        plot_epsilon,
        plot_individual_agents,
        plot_method_curves,
        save_figure,
    )
    from analysis.intervals import (
        bootstrap_interval,
        difference_intervals,
        iqm,
        method_intervals,
    )
    from analysis.paper import paper_comparison
    from analysis.report import ReportResult, write_report
    from analysis.stats import (
        agent_totals,
        correlation_matrix,
        improvement_pct,
        method_correlations,
        method_curves,
        method_totals,
        student_t_test,
        t_tests,
    )
    from analysis.summary import Analysis, analyze


def __getattr__(name: str) -> Any:
    if name not in _MODULE_OF:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{_MODULE_OF[name]}"), name)
