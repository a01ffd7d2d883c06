"""The paper's analysis over an episode table: R_T, t-tests, correlations, figures, report.

Pure functions over pandas DataFrames; nothing here reads the database. The table is one
row per (session, episode) — see `server.analysis.episodes.CONTRACT` — and
`write_report(episodes_df, out_dir)` is the entry point for the CLI and the dashboard.
"""

from server.analysis.episodes import (
    CONTRACT,
    METHOD_NAMES,
    EpisodeTableError,
    method_name,
    order_methods,
    reward_curves,
    validate_episodes,
)
from server.analysis.figures import (
    plot_correlation,
    plot_cumulative_reward,
    plot_epsilon,
    plot_individual_agents,
    plot_method_curves,
    save_figure,
)
from server.analysis.intervals import (
    bootstrap_interval,
    difference_intervals,
    iqm,
    method_intervals,
)
from server.analysis.paper import paper_comparison
from server.analysis.report import ReportResult, write_report
from server.analysis.stats import (
    agent_totals,
    correlation_matrix,
    improvement_pct,
    method_correlations,
    method_curves,
    method_totals,
    student_t_test,
    t_tests,
)
from server.analysis.summary import Analysis, analyze
from server.analysis.synthetic import synthetic_episodes

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
    "synthetic_episodes",
    "t_tests",
    "validate_episodes",
    "write_report",
]
