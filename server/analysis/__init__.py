"""The paper's analysis over an episode table: R_T, t-tests, correlations.

Pure functions over pandas DataFrames; nothing here reads the database. The table is one
row per (session, episode) — see `server.analysis.episodes.CONTRACT`.
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
from server.analysis.paper import paper_comparison
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

__all__ = [
    "CONTRACT",
    "METHOD_NAMES",
    "EpisodeTableError",
    "agent_totals",
    "correlation_matrix",
    "improvement_pct",
    "method_correlations",
    "method_curves",
    "method_name",
    "method_totals",
    "order_methods",
    "paper_comparison",
    "reward_curves",
    "student_t_test",
    "t_tests",
    "validate_episodes",
]
