"""The paper's statistics against values worked out by hand and against scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from analysis import (
    EpisodeTableError,
    agent_totals,
    correlation_matrix,
    method_correlations,
    method_curves,
    method_totals,
    student_t_test,
    t_tests,
)
from analysis import markdown as md
from analysis.paper import PAPER_EPISODES, PAPER_T_TESTS
from tests.analysis.helpers import HAND_CASE, episodes_from_curves


def test_r_t_per_agent_is_the_sum_of_its_rewards_with_improvement_over_the_baseline() -> None:
    agents = agent_totals(episodes_from_curves(HAND_CASE)).set_index("label")
    assert agents["R_T"].to_dict() == {
        "DeepRL1": 3.0,
        "DeepRL2": 5.0,
        "agent-IDeepRL1": 6.0,
        "agent-IDeepRL2": 8.0,
        "human-IDeepRL1": 9.0,
    }
    # the autonomous method's R_T is 4: (3 - 4) / 4 = -25 %, (8 - 4) / 4 = +100 %
    assert agents.loc["DeepRL1", "improvement_pct"] == pytest.approx(-25.0)
    assert agents.loc["agent-IDeepRL2", "improvement_pct"] == pytest.approx(100.0)
    assert agents.loc["agent-IDeepRL2", "mean_reward"] == pytest.approx(8.0 / 3)
    assert set(agents["episodes"]) == {3}


def test_r_t_per_method_is_the_sum_of_its_average_curve() -> None:
    methods = method_totals(episodes_from_curves(HAND_CASE)).set_index("method")
    assert list(methods.index) == ["autonomous", "agent", "human"]
    # autonomous average curve: 1.5, 0.5, 2.0 -> 4.0; agent: 1.5, 2.5, 3.0 -> 7.0
    assert methods["R_T"].to_dict() == pytest.approx(
        {"autonomous": 4.0, "agent": 7.0, "human": 9.0}
    )
    assert methods["improvement_pct"].to_dict() == pytest.approx(
        {"autonomous": 0.0, "agent": 75.0, "human": 125.0}
    )
    assert methods.loc["agent", "R_T_std"] == pytest.approx(math.sqrt(2.0))
    assert (methods.loc["agent", "R_T_min"], methods.loc["agent", "R_T_max"]) == (6.0, 8.0)
    assert math.isnan(methods.loc["human", "R_T_std"])
    assert methods["agents"].to_dict() == {"autonomous": 2, "agent": 2, "human": 1}
    assert methods.loc["agent", "name"] == "agent-IDeepRL"


def test_the_improvement_uses_the_baseline_of_your_choice_and_no_percent_of_a_negative_one() -> (
    None
):
    negative = {"a": ("autonomous", [-3.0, -1.0]), "b": ("agent", [-1.0, -1.0])}
    methods = method_totals(episodes_from_curves(negative)).set_index("method")
    # from -4 to -2: no percentage of -4 (it read as +50 %); the difference is in points
    assert math.isnan(methods.loc["agent", "improvement_pct"])
    assert methods.loc["agent", "difference"] == pytest.approx(2.0)
    assert md.versus(methods.loc["agent", "R_T"], methods.loc["autonomous", "R_T"]) == (
        "+2.00 points"
    )
    assert md.versus(7.0, 4.0) == "+75.00 %"
    assert md.versus(1.0, 0.0) == "+1.00 points"
    by_agent = method_totals(episodes_from_curves(HAND_CASE), baseline="agent").set_index("method")
    assert by_agent.index[0] == "agent"
    assert by_agent.loc["human", "improvement_pct"] == pytest.approx((9 - 7) / 7 * 100)
    zero = {"a": ("autonomous", [1.0, -1.0]), "b": ("agent", [1.0, 1.0])}
    assert math.isnan(
        method_totals(episodes_from_curves(zero))
        .set_index("method")
        .loc["agent", "improvement_pct"]
    )
    none = method_totals(episodes_from_curves(HAND_CASE), baseline=None)
    assert none["improvement_pct"].isna().all()


def test_a_baseline_without_sessions_is_refused_with_the_methods_present() -> None:
    with pytest.raises(
        EpisodeTableError, match=r"'random' has no sessions.*autonomous, agent, human"
    ):
        method_totals(episodes_from_curves(HAND_CASE), baseline="random")


def test_outcome_counts_are_averaged_per_episode() -> None:
    misplaced = {
        label: [1, 0, 0] if method == "autonomous" else [0, 0, 0]
        for label, (method, _) in HAND_CASE.items()
    }
    methods = method_totals(episodes_from_curves(HAND_CASE, misplaced=misplaced)).set_index(
        "method"
    )
    assert methods.loc["autonomous", "misplaced_per_episode"] == pytest.approx(1 / 3)
    assert methods.loc["agent", "misplaced_per_episode"] == 0.0
    assert "lost_per_episode" not in methods


def test_method_curves_are_mean_and_sample_std_across_agents() -> None:
    curves = method_curves(episodes_from_curves(HAND_CASE)).set_index(["method", "episode"])
    assert curves.loc[("agent", 3), "mean"] == 3.0
    assert curves.loc[("agent", 3), "std"] == pytest.approx(math.sqrt(2.0))  # 2 and 4, ddof=1
    assert curves.loc[("agent", 3), "agents"] == 2


def test_student_t_test_matches_a_hand_computation_and_scipy() -> None:
    a, b = np.array([1.0, 2, 3, 4, 5]), np.array([2.0, 4, 6, 8, 10])
    t, p = student_t_test(a, b)
    # pooled variance (4 * 2.5 + 4 * 10) / 8 = 6.25; se = sqrt(6.25 * 2 / 5) = sqrt(2.5)
    assert t == pytest.approx(-3.0 / math.sqrt(2.5))
    assert p == pytest.approx(2 * stats.t.sf(3.0 / math.sqrt(2.5), 8))
    assert (t, p) == pytest.approx(tuple(stats.ttest_ind(a, b)))
    assert all(math.isnan(x) for x in student_t_test(a[:1], b))


def test_table_2_compares_the_average_curves_and_we_add_the_agents_r_t() -> None:
    rng = np.random.default_rng(5)
    curves = {f"DeepRL{i}": ("autonomous", rng.normal(0.0, 1.0, 40)) for i in range(3)}
    curves |= {f"agent-IDeepRL{i}": ("agent", rng.normal(0.8, 1.0, 40)) for i in range(4)}
    table = episodes_from_curves(curves)
    tests = t_tests(table).set_index(["method_a", "method_b", "sample"])
    assert list(tests.index) == [
        ("agent", "autonomous", "episode_means"),
        ("agent", "autonomous", "agent_totals"),
    ]
    mean_agent = np.mean([curves[f"agent-IDeepRL{i}"][1] for i in range(4)], axis=0)
    mean_auto = np.mean([curves[f"DeepRL{i}"][1] for i in range(3)], axis=0)
    expected = stats.ttest_ind(mean_agent, mean_auto)
    curve = tests.loc[("agent", "autonomous", "episode_means")]
    assert (curve["t"], curve["p"]) == pytest.approx((expected.statistic, expected.pvalue))
    assert (curve["n_a"], curve["n_b"], curve["df"]) == (40, 40, 78)
    assert curve["mean_a"] == pytest.approx(mean_agent.mean())
    totals_agent = [sum(curves[f"agent-IDeepRL{i}"][1]) for i in range(4)]
    totals_auto = [sum(curves[f"DeepRL{i}"][1]) for i in range(3)]
    expected = stats.ttest_ind(totals_agent, totals_auto)
    per_agent = tests.loc[("agent", "autonomous", "agent_totals")]
    assert (per_agent["t"], per_agent["p"]) == pytest.approx((expected.statistic, expected.pvalue))
    assert (per_agent["n_a"], per_agent["n_b"], per_agent["df"]) == (4, 3, 5)
    assert curve["t"] > 0  # agent-IDeepRL collects more than the baseline here
    assert "equal variances" in curve["test"]


def test_welch_is_available_and_matches_scipy() -> None:
    table = episodes_from_curves(
        {"a": ("autonomous", [0.0, 1.0, 0.5, 0.2]), "b": ("agent", [1.0, 5.0, 2.0, 9.0])}
    )
    row = t_tests(table, equal_var=False).iloc[0]
    expected = stats.ttest_ind([1.0, 5.0, 2.0, 9.0], [0.0, 1.0, 0.5, 0.2], equal_var=False)
    assert (row["t"], row["p"]) == pytest.approx((expected.statistic, expected.pvalue))
    assert row["df"] == pytest.approx(expected.df)


def test_every_pair_is_tested_baseline_last_and_single_agents_give_no_per_agent_test() -> None:
    tests = t_tests(episodes_from_curves(HAND_CASE))
    pairs = list(dict.fromkeys(zip(tests["method_a"], tests["method_b"], strict=True)))
    assert pairs == [("agent", "autonomous"), ("human", "autonomous"), ("agent", "human")]
    human = tests[(tests["method_a"] == "human") & (tests["sample"] == "agent_totals")].iloc[0]
    assert human["n_a"] == 1 and math.isnan(human["t"]) and math.isnan(human["p"])


def test_the_papers_p_values_follow_from_its_t_with_300_episode_means_per_sample() -> None:
    """Why Table 2 is a test on average curves: only 2 x 300 - 2 degrees of freedom fit."""
    for t, p in PAPER_T_TESTS.values():
        assert 2 * stats.t.sf(t, 2 * PAPER_EPISODES - 2) == pytest.approx(p, rel=2e-3)
        assert 2 * stats.t.sf(t, 2 * 10 - 2) != pytest.approx(p, rel=0.02)


def test_correlation_of_constructed_curves() -> None:
    x = np.array([0.0, 1.0, 3.0, 2.0, 5.0, 4.0])
    curves = {
        "x": ("autonomous", x),
        "same": ("agent", x.copy()),
        "negated": ("agent", -x),
        "scaled": ("human", 2.0 * x + 5.0),
        "flipped": ("human", 1.0 - 0.5 * x),
        "flat": ("human", np.full(6, 2.0)),
    }
    matrix = correlation_matrix(episodes_from_curves(curves))
    order = ["x", "negated", "same", "flat", "flipped", "scaled"]  # by method, then label
    assert list(matrix.index) == list(matrix.columns) == order
    assert matrix.loc["x", "same"] == pytest.approx(1.0)
    assert matrix.loc["x", "negated"] == pytest.approx(-1.0)
    assert matrix.loc["x", "scaled"] == pytest.approx(1.0)
    assert matrix.loc["x", "flipped"] == pytest.approx(-1.0)
    assert matrix.loc["negated", "flipped"] == pytest.approx(1.0)
    assert matrix.loc["flat"].isna().all() and matrix["flat"].isna().all()
    assert np.allclose(matrix.to_numpy(), matrix.to_numpy().T, equal_nan=True)


def test_correlation_matches_pearsonr_and_is_zero_for_orthogonal_curves() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=30), rng.normal(size=30)
    u, v = np.tile([1.0, -1.0, 1.0, -1.0], 2), np.tile([1.0, 1.0, -1.0, -1.0], 2)
    matrix = correlation_matrix(episodes_from_curves({"a": ("agent", a), "b": ("agent", b)}))
    assert matrix.loc["a", "b"] == pytest.approx(stats.pearsonr(a, b).statistic)
    ortho = correlation_matrix(episodes_from_curves({"u": ("agent", u), "v": ("human", v)}))
    assert ortho.loc["u", "v"] == pytest.approx(0.0, abs=1e-12)


def test_correlation_picks_agents_by_label_and_names_unknown_ones() -> None:
    table = episodes_from_curves(HAND_CASE)
    picked = correlation_matrix(table, ["human-IDeepRL1", "DeepRL2"])
    assert list(picked.index) == ["human-IDeepRL1", "DeepRL2"]
    with pytest.raises(EpisodeTableError, match=r"no agent labelled 'H9'\. Pick from: DeepRL1"):
        correlation_matrix(table, ["H9"])


def test_method_correlations_average_the_pairs_between_methods() -> None:
    x = np.array([0.0, 1.0, 3.0, 2.0])
    curves = {
        "a1": ("autonomous", x),
        "a2": ("autonomous", -x),
        "g1": ("agent", x),
        "g2": ("agent", x),
    }
    table = episodes_from_curves(curves)
    summary = method_correlations(table, correlation_matrix(table)).set_index(
        ["method_a", "method_b"]
    )
    assert summary.loc[("autonomous", "autonomous"), "mean_r"] == pytest.approx(-1.0)
    assert summary.loc[("autonomous", "autonomous"), "pairs"] == 2
    assert summary.loc[("agent", "agent"), "mean_r"] == pytest.approx(1.0)
    # a1 and a2 against g1, g2: +1, +1, -1, -1
    assert summary.loc[("autonomous", "agent"), "mean_r"] == pytest.approx(0.0)
    assert summary.loc[("autonomous", "agent"), "pairs"] == 4


def test_two_constant_samples_are_no_test() -> None:
    """Every value equal in each: t is d/0, undefined, as its docstring says (scipy gives
    t = -inf, p = 0: 'significant'), and as the power simulation counts such a study."""
    t, p = student_t_test(np.array([0.1, 0.1, 0.1]), np.array([0.2, 0.2, 0.2]))
    assert math.isnan(t) and math.isnan(p)
    t, p = student_t_test(np.array([0.1, 0.1, 0.1]), np.array([0.2, 0.3, 0.2]))
    assert not math.isnan(p), "one constant sample beside a varying one is a test"


def test_the_success_rate_is_the_share_of_a_methods_episodes_that_succeeded() -> None:
    """Hand-computed: the autonomous agents' episodes succeed in the second half only."""
    episodes = episodes_from_curves(HAND_CASE)
    half = episodes["episode"] > episodes["episode"].max() / 2
    episodes = episodes.assign(success=half & (episodes["method"] == "autonomous"))
    methods = method_totals(episodes).set_index("method")
    expected = half[episodes["method"] == "autonomous"].mean()
    assert methods.loc["autonomous", "success_rate"] == pytest.approx(expected)
    assert methods.loc["agent", "success_rate"] == 0.0
    assert "success_rate" not in method_totals(episodes_from_curves(HAND_CASE))
