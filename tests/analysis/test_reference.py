"""The authors' published curves as the reference of Figure 5 (`--reference authors`)."""

from __future__ import annotations

import pandas as pd
import pytest
from matplotlib.figure import Figure

from analysis.reference import AUTHORS_CURVES, authors_totals, overlay_authors


def test_the_authors_curves_sum_to_the_papers_totals() -> None:
    """The paper's R_T are the sums of these two curves (reference/README.md: 367.85 for
    their autonomous curve, 606.85 for the agent-advised one; printed 369.88 and 606.70)."""
    totals = authors_totals(300).set_index("method")
    assert totals.loc["autonomous", "authors_curve_R_T"] == pytest.approx(367.85, abs=0.01)
    assert totals.loc["agent", "authors_curve_R_T"] == pytest.approx(606.85, abs=0.01)
    assert totals.loc["autonomous", "paper_R_T"] == pytest.approx(369.88, abs=0.01)
    assert totals.loc["agent", "paper_R_T"] == pytest.approx(606.70, abs=0.01)
    assert list(totals["scheme"]) == ["authors-autonomous", "authors-interactive"]
    assert list(totals["episodes"]) == [300, 300]
    first = authors_totals(50).set_index("method")
    raw = pd.read_csv(AUTHORS_CURVES)
    expected = raw.loc[raw["episode"] <= 50, "agent_mean_reward"].sum()
    assert first.loc["agent", "authors_curve_R_T"] == pytest.approx(expected)


def test_the_overlay_draws_each_curve_dashed_in_its_methods_colour() -> None:
    figure = Figure()
    ax = figure.add_subplot()
    ours = {}
    for method, color in (("autonomous", "tab:blue"), ("agent", "tab:orange")):
        (ours[method],) = ax.plot([1, 2], [0, 1], color=color)
    overlay_authors(figure, ["autonomous", "agent"], n_episodes=120)
    dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == 2
    for line in dashed:
        assert len(line.get_xdata()) == 120 and max(line.get_xdata()) == 120
    assert "the authors' mean" in dashed[0].get_label()
