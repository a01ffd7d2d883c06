"""The participant as the unit: each measure of a small hand-written study against the
same worked out by hand."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from analysis.between import fisher, holm, mann_whitney, welch
from analysis.human import between_conditions, check_rates, flow, participants
from analysis.human_report import human_section
from tests.analysis.visits import hand_visits, rated_visits


def test_the_flow_counts_the_sessions_outcomes_by_condition() -> None:
    counts = flow(hand_visits()).set_index("condition")
    assert counts.loc["early"].to_dict() == {
        "arrived": 5, "declined": 1, "consented": 4, "excluded": 1, "timed_out": 0,
        "completed": 3, "under_way": 0,
    }  # fmt: skip
    assert counts.loc["late"].to_dict() == {
        "arrived": 4, "declined": 0, "consented": 4, "excluded": 0, "timed_out": 1,
        "completed": 2, "under_way": 1,
    }  # fmt: skip
    assert list(counts.index) == ["early", "late"]  # session 10 has no condition: no visit


def test_each_completed_participants_advice_accuracy_and_decision_time() -> None:
    people = participants(hand_visits()).set_index("session_id")
    assert list(people.index) == [1, 2, 3, 6, 7]  # completed visits only
    assert people["advice"].to_dict() == {1: 3, 2: 2, 3: 1, 6: 2, 7: 2}  # none given: not one
    assert people["accuracy"].to_dict() == pytest.approx({1: 2 / 3, 2: 1.0, 3: 0.0, 6: 0.5, 7: 1.0})
    assert people["median_decision_s"].to_dict() == {1: 2.0, 2: 2.0, 3: 8.0, 6: 2.0, 7: 1.0}
    assert people["first_try"].to_dict() == {1: True, 2: False, 3: True, 6: True, 7: True}
    assert people["scale_trust"].to_dict() == {1: 5.0, 2: 6.0, 3: 4.0, 6: 3.0, 7: 2.0}


def test_no_accuracy_without_a_recorded_correct_action() -> None:
    visits = hand_visits()
    visits = type(visits)(
        visits.sessions, visits.advice.drop(columns="correct_action"), visits.check,
        visits.questionnaire, visits.scales,
    )  # fmt: skip
    assert not visits.correct_action_recorded
    assert participants(visits)["accuracy"].isna().all()
    assert "accuracy" not in set(between_conditions(visits, 0.05)["measure"])


def test_ratings_are_a_participants_turns_where_their_session_has_them() -> None:
    people = participants(rated_visits()).set_index("session_id")
    assert people["gave"].to_dict() == {
        1: "advice", 2: "advice", 3: "advice", 6: "ratings", 7: "ratings"
    }  # fmt: skip
    assert people["advice"].to_dict() == {1: 3, 2: 2, 3: 1, 6: 3, 7: 2}  # no answer: not one
    # a rating is right when it says good of the correct action or bad of another; 0: neither
    assert people["accuracy"].to_dict() == pytest.approx(
        {1: 2 / 3, 2: 1.0, 3: 0.0, 6: 2 / 3, 7: 0.0}
    )
    assert people["median_decision_s"].to_dict() == {1: 2.0, 2: 2.0, 3: 8.0, 6: 3.0, 7: 1.0}
    tests = between_conditions(rated_visits(), 0.05).set_index("measure")
    assert "advice or ratings given" in tests.index and "advice given" not in tests.index
    # late's accuracy: 2/3 and 0, the participant as the unit
    assert tests.loc["accuracy", "n_b"] == 2


def test_ratings_without_a_correct_action_have_no_accuracy(tmp_path: Path) -> None:
    visits = rated_visits(correct_action=False)
    people = participants(visits).set_index("session_id")
    assert people["accuracy"].loc[[6, 7]].isna().all()
    assert people["accuracy"].loc[[1, 2, 3]].tolist() == pytest.approx([2 / 3, 1.0, 0.0])
    lines, _ = human_section(visits, tmp_path, 0.05)
    text = "\n".join(lines)
    assert "No accuracy for ratings: the feedback table records no correct action" in text
    assert "Accuracy of advice is the share" in text
    # per condition: late gave ratings, 2.5 of them on average, median of medians 2.0 s
    assert "| late | 2 | ratings | 2.50 | – | 2.00 |" in text


def test_an_action_as_right_as_the_correct_one_counts_as_right() -> None:
    """Where a row lists every right action (`correct_actions`: the grid world's moves
    equally near the goal), advice naming any of them is accurate and a rating is right
    when it says good of one of them or bad of another; a row without the list (stored
    before it was recorded) reads its `correct_action` alone."""
    visits = rated_visits()
    advice = visits.advice.assign(correct_actions=None)
    # session 1's third advice names 2 where 3 is the correct action and 2 is as right
    advice.loc[(advice["session_id"] == 1) & (advice["action"] == 2), "correct_actions"] = "2 3"
    # session 3's advice of 1 where 2 is correct and 1 is not among the right ones
    advice.loc[(advice["session_id"] == 3) & (advice["action"] == 1), "correct_actions"] = "2 3"
    feedback = visits.feedback.assign(correct_actions=None)
    feedback.loc[1, "correct_actions"] = "1 2"  # 6's good of 1 (correct 2): 1 is as right
    people = _people(visits, advice, feedback)
    assert people["accuracy"].to_dict() == pytest.approx({1: 1.0, 2: 1.0, 3: 0.0, 6: 1.0, 7: 0.0})
    feedback.loc[1, "correct_actions"] = None
    feedback.loc[2, "correct_actions"] = "0 2"  # 6's bad of 2 (correct 0): 2 is as right
    people = _people(visits, advice, feedback)
    assert people["accuracy"].loc[6] == pytest.approx(1 / 3)
    before = participants(visits).set_index("session_id")
    assert before["accuracy"].to_dict() == pytest.approx(
        {1: 2 / 3, 2: 1.0, 3: 0.0, 6: 2 / 3, 7: 0.0}
    )


def _people(visits, advice, feedback):
    listed = type(visits)(
        visits.sessions, advice, visits.check, visits.questionnaire, visits.scales, feedback
    )
    return participants(listed).set_index("session_id")


def test_the_checks_pass_rates_count_everyone_who_took_it() -> None:
    rates = check_rates(hand_visits()).set_index("condition")
    assert rates.loc["early"].to_dict() == {"took": 4, "first_try": 2, "passed": 3}
    assert rates.loc["late"].to_dict() == {"took": 3, "first_try": 2, "passed": 3}


def test_welch_on_trust_by_hand() -> None:
    # early 5, 6, 4: mean 5, var 1; late 3, 2: mean 2.5, var 0.5
    se = math.sqrt(1 / 3 + 0.5 / 2)
    df = (1 / 3 + 0.25) ** 2 / ((1 / 3) ** 2 / 2 + 0.25**2 / 1)
    tested = welch([5, 6, 4], [3, 2], alpha=0.05)
    assert tested.statistic == pytest.approx(2.5 / se)
    assert tested.estimate == pytest.approx(2.5)
    from scipy import stats

    half = stats.t.ppf(0.975, df) * se
    assert (tested.low, tested.high) == pytest.approx((2.5 - half, 2.5 + half))
    assert tested.p == pytest.approx(2 * stats.t.sf(2.5 / se, df))


def test_decision_times_are_compared_on_a_log_scale() -> None:
    tested = welch([2.0, 2.0, 8.0], [2.0, 1.0], alpha=0.05, log=True)
    # geometric means: (2 * 2 * 8) ** (1/3) = 32 ** (1/3); sqrt(2)
    assert tested.estimate == pytest.approx(32 ** (1 / 3) / math.sqrt(2))
    assert tested.low < tested.estimate < tested.high


def test_mann_whitney_and_its_rank_biserial_by_hand() -> None:
    # a = 50, 70, 60 above b = 20, 30 in all 6 pairs: U = 6, r = 2 * 6 / 6 - 1 = 1
    tested = mann_whitney([50, 70, 60], [20, 30], alpha=0.05)
    assert tested.statistic == 6 and tested.estimate == pytest.approx(1.0)
    assert tested.p == pytest.approx(0.2)  # 2 of the 10 orderings are as extreme
    assert tested.low < 1.0 and tested.high == pytest.approx(1.0)


def test_fisher_and_newcombes_interval_by_hand() -> None:
    tested = fisher(3, 4, 0, 4, alpha=0.05)
    # 3 successes of 8, 4 in a: P(k in a) = C(4, k) C(4, 3 - k) / C(8, 3) = 4, 24, 24, 4 / 56;
    # as unlikely as k = 3 or less: k = 0 and k = 3
    assert tested.p == pytest.approx(8 / 56)
    assert tested.estimate == pytest.approx(0.75)
    assert tested.low < 0.75 < tested.high <= 1.0


def test_holm_adjusts_within_a_family_and_skips_what_was_not_tested() -> None:
    adjusted = holm([0.01, float("nan"), 0.04, 0.03])
    # three tests: 0.01 * 3, then max(0.03, 0.03 * 2), then max(0.06, 0.04 * 1)
    assert adjusted[0] == pytest.approx(0.03)
    assert math.isnan(adjusted[1])
    assert adjusted[3] == pytest.approx(0.06) and adjusted[2] == pytest.approx(0.06)


def test_one_participant_in_a_group_gets_no_test() -> None:
    for tested in (welch([1.0], [2.0, 3.0], 0.05), mann_whitney([1], [2, 3], 0.05),
                   fisher(1, 1, 0, 2, 0.05)):  # fmt: skip
        assert math.isnan(tested.p)
        assert tested.no_test == "fewer than two participants in a group"
    visits = hand_visits()
    one = visits.sessions.assign(
        outcome=visits.sessions["outcome"].where(visits.sessions["session_id"] != 7, "timed_out")
    )  # late keeps one completed visit
    tests = between_conditions(type(visits)(one, *list(visits.__dict__.values())[1:]), 0.05)
    per_person = tests[tests["family"].isin(["advice", "scales", "items"])]
    assert per_person["p"].isna().all() and (per_person["significant"].isna()).all()
    assert set(per_person["no_test"]) == {"fewer than two participants in a group"}


def test_no_variation_gets_no_test() -> None:
    tests = between_conditions(hand_visits(), 0.05).set_index("measure")
    assert tests.loc["custom/fun", "no_test"].startswith("no variation")  # everyone said 4
    assert np.isnan(tests.loc["custom/fun", "p"])
    assert tests.loc["trust", "p_holm"] == pytest.approx(tests.loc["trust", "p"])  # alone
