"""The paper's published numbers, and our results set beside them.

Moreira et al., "Results": R_T of the three methods over N = 300 episodes (ten agents
each), the improvement over autonomous DeepRL, and Table 2's t-tests, which compare the
methods' average curves (N = 300 values per sample, see `stats.py`).
"""

from __future__ import annotations

import pandas as pd

from analysis.episodes import method_name
from analysis.markdown import count
from analysis.stats import EPISODE_MEANS

PAPER_EPISODES = 300
"""Episodes per agent in the paper."""

PAPER_AGENTS = 10
"""Agents per method in the paper's Figure 5."""

PAPER_R_T: dict[str, float] = {"autonomous": 369.8788, "agent": 606.6995, "human": 589.5974}
"""Total collected reward R_T per method."""

PAPER_IMPROVEMENT_PCT: dict[str, float] = {"agent": 64.03, "human": 59.40}
"""Improvement in percent over autonomous DeepRL."""

PAPER_T_TESTS: dict[tuple[str, str], tuple[float, float]] = {
    ("autonomous", "agent"): (7.6829, 6.3947e-14),
    ("autonomous", "human"): (7.0192, 6.0755e-12),
    ("agent", "human"): (0.8461, 0.3978),
}
"""Table 2: (|t|, p) for each pair of methods, on the average curves."""


def paper_comparison(
    method_totals: pd.DataFrame, t_tests: pd.DataFrame, *, baseline: str | None = "autonomous"
) -> pd.DataFrame:
    """Rows of (quantity, paper, ours, our_sample) for every published number we can match.

    A number appears only when the methods it needs are in our data; the improvement only
    when our baseline is the paper's (autonomous). Columns: quantity, paper, ours, sample.
    """
    totals = method_totals.set_index("method")
    rows: list[dict[str, object]] = []
    for method, published in PAPER_R_T.items():
        if method in totals.index:
            ours = totals.loc[method]
            rows.append(
                {
                    "quantity": f"R_T {method_name(method)}",
                    "paper": published,
                    "ours": float(ours["R_T"]),
                    "sample": f"{count(int(ours['agents']), 'agent')} × "
                    f"{count(int(ours['episodes']), 'episode')} "
                    f"(paper: {PAPER_AGENTS} × {PAPER_EPISODES})",
                }
            )
    if baseline == "autonomous":
        for method, published in PAPER_IMPROVEMENT_PCT.items():
            if method in totals.index and baseline in totals.index:
                rows.append(
                    {
                        "quantity": f"improvement {method_name(method)} over "
                        f"{method_name(baseline)} (%)",
                        "paper": published,
                        "ours": float(totals.loc[method, "improvement_pct"]),
                        "sample": "R_T of the methods",
                    }
                )
    curve_tests = t_tests[t_tests["sample"] == EPISODE_MEANS]
    for (method_a, method_b), (t, p) in PAPER_T_TESTS.items():
        match = curve_tests[
            ((curve_tests["method_a"] == method_a) & (curve_tests["method_b"] == method_b))
            | ((curve_tests["method_a"] == method_b) & (curve_tests["method_b"] == method_a))
        ]
        if match.empty:
            continue
        ours = match.iloc[0]
        pair = f"{method_name(method_a)} vs {method_name(method_b)}"
        sample = f"average curves, n = {int(ours['n_a'])} + {int(ours['n_b'])}"
        rows.append(
            {"quantity": f"|t| {pair}", "paper": t, "ours": abs(ours["t"]), "sample": sample}
        )
        rows.append({"quantity": f"p {pair}", "paper": p, "ours": ours["p"], "sample": sample})
    return pd.DataFrame(rows, columns=["quantity", "paper", "ours", "sample"])
