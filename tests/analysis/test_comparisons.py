"""The primary test and the secondary ones (analysis.comparisons), against scipy and
small cases worked by hand; and the report leading with the primary test."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.comparisons import compare, comparison_pairs, probability_of_improvement
from analysis.report import write_report


def _episodes(totals: dict[str, list[float]], seeds: dict[str, list[int]]) -> pd.DataFrame:
    """Two episodes per agent whose rewards sum to the given R_T."""
    rows, session = [], 0
    for method, values in totals.items():
        for value, seed in zip(values, seeds[method], strict=True):
            session += 1
            for episode, share in ((1, 0.4), (2, 0.6)):
                rows.append((session, method, seed, episode, value * share))
    return pd.DataFrame(
        rows, columns=["session_id", "method", "seed", "episode", "collected_reward"]
    )


def test_probability_of_improvement_counts_pairs_and_half_ties() -> None:
    assert probability_of_improvement(np.array([3.0]), np.array([1.0, 2.0])) == 1.0
    assert probability_of_improvement(np.array([1.0, 2.0]), np.array([2.0])) == pytest.approx(0.25)


def test_welch_is_primary_and_the_secondary_tests_are_scipys() -> None:
    a, b = [10.0, 12.0, 15.0, 11.0], [8.0, 9.0, 7.5, 10.5]
    table = _episodes(
        {"autonomous": b, "agent": a}, {"autonomous": [0, 1, 2, 3], "agent": [0, 1, 2, 3]}
    )
    (row,) = compare(table, "autonomous").itertuples()
    assert row.primary == "welch"
    assert row.primary_p == pytest.approx(stats.ttest_ind(a, b, equal_var=False).pvalue)
    assert row.mann_whitney_p == pytest.approx(stats.mannwhitneyu(a, b).pvalue)
    assert row.paired_p == pytest.approx(stats.ttest_rel(a, b).pvalue)
    assert row.n_paired == 4 and row.difference == pytest.approx(np.mean(a) - np.mean(b))
    # 4 + 4 agents: 70 distinct splits, so the permutation test is exact. As extreme as the
    # observed split: itself and the one swapping 10 and 10.5 (a larger difference), and
    # their mirror images on the other side
    assert row.permutation_p == pytest.approx(4 / 70)
    assert row.poi_low <= row.probability_of_improvement <= row.poi_high


def test_the_paired_test_is_primary_only_where_every_seed_pairs() -> None:
    a, b = [10.0, 12.0, 15.0], [8.0, 9.0, 7.5]
    paired = _episodes({"autonomous": b, "agent": a}, {"autonomous": [0, 1, 2], "agent": [0, 1, 2]})
    (row,) = compare(paired, "autonomous", primary="paired").itertuples()
    assert row.primary == "paired"
    assert row.primary_p == pytest.approx(stats.ttest_rel(a, b).pvalue)
    apart = _episodes({"autonomous": b, "agent": a}, {"autonomous": [0, 1, 2], "agent": [5, 6, 7]})
    (row,) = compare(apart, "autonomous", primary="paired").itertuples()
    assert row.primary == "welch (seeds do not pair)" and row.n_paired == 0
    assert row.primary_p == pytest.approx(stats.ttest_ind(a, b, equal_var=False).pvalue)


@pytest.mark.slow
def test_the_report_leads_with_the_primary_test(tmp_path: Path) -> None:
    a, b = [10.0, 12.0, 15.0, 11.0], [8.0, 9.0, 7.5, 10.5]
    table = _episodes(
        {"autonomous": b, "agent": a}, {"autonomous": [0, 1, 2, 3], "agent": [0, 1, 2, 3]}
    )
    text = write_report(table, tmp_path).report.read_text()
    assert text.index("## The primary test, then the secondary ones") < text.index(
        "## The paper's own test"
    )
    summary = text[text.index("## In short") : text.index("## The primary test")]
    assert summary.index("Primary test (Welch's t-test") < summary.index("the paper's own test")
    assert (tmp_path / "primary_and_secondary_tests.csv").is_file()


def test_each_judged_arm_is_compared_with_the_control_of_its_kind() -> None:
    from analysis.episodes import arm

    methods = [
        "autonomous", "oracle", "procedure", arm("oracle", "evaluative"),
        arm("procedure", "evaluative"), arm("agent", "evaluative", "rating_model"),
        arm("procedure", "evaluative", "rating_model"), "sb3-dqn",
    ]  # fmt: skip
    pairs = comparison_pairs(methods, "autonomous")
    assert [p for p in pairs if p[1] != "autonomous"] == [
        ("oracle", "procedure"),
        ("oracle-evaluative", "procedure-evaluative"),
        ("agent-evaluative-rating_model", "procedure-evaluative-rating_model"),
    ]
    assert len(pairs) == len(methods) - 1 + 3
