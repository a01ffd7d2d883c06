"""Welch's test, bootstrap intervals and the IQM: against scipy, and against cases whose
intervals are known exactly or in closed form."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis import (
    bootstrap_interval,
    difference_intervals,
    iqm,
    method_intervals,
    t_tests,
    write_report,
)
from analysis.report import TABLE_FILES
from tests.analysis.helpers import HAND_CASE, episodes_from_curves


def agents_with_totals(totals: dict[str, list[float]]) -> pd.DataFrame:
    """One-episode agents, so each agent's R_T is the given number."""
    curves = {
        f"{method}-{i}": (method, [value])
        for method, values in totals.items()
        for i, value in enumerate(values, start=1)
    }
    return episodes_from_curves(curves)


def test_welch_is_reported_beside_student_and_matches_scipy() -> None:
    table = episodes_from_curves(HAND_CASE)
    tests = t_tests(table).set_index(["method_a", "method_b", "sample"])
    row = tests.loc[("agent", "autonomous", "agent_totals")]
    welch = stats.ttest_ind([6.0, 8.0], [3.0, 5.0], equal_var=False)
    student = stats.ttest_ind([6.0, 8.0], [3.0, 5.0])
    assert (row["t"], row["p"]) == pytest.approx((student.statistic, student.pvalue))
    assert (row["t_welch"], row["p_welch"]) == pytest.approx((welch.statistic, welch.pvalue))
    assert row["df_welch"] == pytest.approx(welch.df)
    curves = tests.loc[("agent", "autonomous", "episode_means")]
    expected = stats.ttest_ind([1.5, 2.5, 3.0], [1.5, 0.5, 2.0], equal_var=False)
    assert (curves["t_welch"], curves["p_welch"]) == pytest.approx(
        (expected.statistic, expected.pvalue)
    )
    # One human agent: no test, not a crash.
    assert math.isnan(tests.loc[("human", "autonomous", "agent_totals"), "p_welch"])


def test_unequal_spreads_make_welch_and_student_differ() -> None:
    table = agents_with_totals({"autonomous": [0, 10, 20, 30, 40, 50], "agent": [34, 36]})
    row = t_tests(table).set_index("sample").loc["agent_totals"]
    assert row["df"] == 6 and row["df_welch"] < 6
    assert row["p_welch"] != pytest.approx(row["p"])


def test_iqm_is_the_mean_of_the_middle_half() -> None:
    assert iqm(np.arange(1.0, 9.0)) == pytest.approx(4.5)  # mean of 3, 4, 5, 6
    assert iqm([1.0, 2.0, 3.0, 100.0]) == pytest.approx(2.5)  # one runaway run is cut


def test_a_two_valued_sample_has_the_exactly_known_interval() -> None:
    # Resampled means of [0, 1] are 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4: the 2.5th
    # and 97.5th percentiles are 0 and 1.
    assert bootstrap_interval([np.array([0.0, 1.0])], np.mean) == (0.0, 1.0)
    # 50 % interval: the 25th..75th percentiles of that distribution, 0.5 both.
    assert bootstrap_interval([np.array([0.0, 1.0])], np.mean, confidence=0.4) == (0.5, 0.5)


def test_constant_and_single_agent_samples() -> None:
    assert bootstrap_interval([np.array([3.0, 3.0, 3.0])], np.mean) == (3.0, 3.0)
    low, high = bootstrap_interval([np.array([3.0])], np.mean)
    assert math.isnan(low) and math.isnan(high)


def test_a_large_sample_gives_the_normal_theory_interval() -> None:
    rng = np.random.default_rng(5)
    values = rng.normal(10.0, 2.0, 400)
    low, high = bootstrap_interval([values], np.mean, n_resamples=20_000)
    half = 1.959964 * values.std(ddof=1) / math.sqrt(len(values))
    assert (low, high) == pytest.approx((values.mean() - half, values.mean() + half), abs=0.02)


def test_intervals_per_method_and_per_difference_follow_scipy() -> None:
    totals = {"autonomous": [3.0, 5.0, 4.0, 9.0], "agent": [6.0, 8.0, 7.5, 6.5]}
    table = agents_with_totals(totals)
    methods = method_intervals(table).set_index("method")
    a, b = np.array(totals["agent"]), np.array(totals["autonomous"])
    expected = stats.bootstrap(
        [a], np.mean, n_resamples=10_000, method="percentile", rng=np.random.default_rng(0)
    ).confidence_interval
    row = methods.loc["agent"]
    assert (row["R_T_low"], row["R_T_high"]) == pytest.approx(tuple(expected))
    assert row["R_T_mean"] == pytest.approx(a.mean()) and row["IQM"] == pytest.approx(7.0)
    assert row["R_T_low"] <= row["R_T_mean"] <= row["R_T_high"]
    assert row["IQM_low"] <= row["IQM"] <= row["IQM_high"]

    diff = difference_intervals(table).iloc[0]
    assert (diff["method_a"], diff["method_b"]) == ("agent", "autonomous")
    assert diff["difference"] == pytest.approx(a.mean() - b.mean())
    expected = stats.bootstrap(
        [a, b],
        lambda x, y, axis=-1: x.mean(axis=axis) - y.mean(axis=axis),
        n_resamples=10_000,
        method="percentile",
        rng=np.random.default_rng(0),
    ).confidence_interval
    assert (diff["low"], diff["high"]) == pytest.approx(tuple(expected))


@pytest.mark.slow
def test_the_report_prints_and_writes_the_intervals(tmp_path) -> None:
    table = agents_with_totals({"autonomous": [3.0, 5.0, 4.0], "agent": [6.0, 8.0, 7.0]})
    result = write_report(table, tmp_path)
    written = pd.read_csv(result.tables["intervals"]).set_index("method")
    assert written.loc["agent", "R_T_mean"] == pytest.approx(7.0)
    diffs = pd.read_csv(tmp_path / TABLE_FILES["differences"])
    assert diffs.loc[0, "difference"] == pytest.approx(3.0)
    text = result.report.read_text(encoding="utf-8")
    assert "## Confidence intervals and interquartile mean" in text
    low, high = diffs.loc[0, "low"], diffs.loc[0, "high"]
    assert f"[{low:.2f}, {high:.2f}]" in text
    assert "Welch p" in text
