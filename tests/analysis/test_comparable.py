"""The comparable-window rule on a small study written out by hand: the window every
condition shares, the advised steps' rewards left out, where each condition's advice fell."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from analysis.comparable import comparable, rule, timing_notes
from analysis.comparable_report import comparable_section

REWARDS = {
    1: [1.0, 2.0, 3.0, 4.0], 2: [0.0, 1.0, 1.0, 2.0],  # early
    3: [5.0, 5.0, 2.0, 3.0], 4: [4.0, 1.0, 2.0, 2.0],  # alternating
    5: [1.0, 1.0, 3.0, 0.0],  # importance
}  # fmt: skip
CONDITION = {1: "early", 2: "early", 3: "alternating", 4: "alternating", 5: "importance"}
STRATEGY = {1: "early", 2: "early", 3: "alternating", 4: "alternating", 5: "importance"}


def _episodes() -> pd.DataFrame:
    return pd.DataFrame(
        [
            {"session_id": i, "method": CONDITION[i], "episode": e + 1, "collected_reward": r}
            for i, rewards in REWARDS.items()
            for e, r in enumerate(rewards)
        ]
    )


def _advised() -> pd.DataFrame:
    return pd.DataFrame(
        [
            (1, "pretrain", 1, 0.0), (1, "pretrain", 2, 1.0), (1, "pretrain", 2, 0.0),
            (2, "pretrain", 1, 1.0),
            (3, "train", 1, 1.0), (3, "train", 1, 0.5), (3, "train", 2, 1.0),
            (4, "train", 1, 1.0),
            (5, "train", 3, 1.0), (5, "train", 4, -1.0),
        ],
        columns=["session_id", "stage", "episode", "reward"],
    )  # fmt: skip


def test_the_window_starts_after_the_last_alternating_advised_episode() -> None:
    found = comparable(_episodes(), _advised(), STRATEGY)
    assert (found.first, found.last) == (3, 4)  # learner 3's last advised episode is 2
    scores = found.scores.set_index("session_id")
    # episodes 3-4: 3 + 4, 1 + 2, 2 + 3, 2 + 2; learner 5: (3 - 1) + (0 - -1)
    assert scores["score"].to_dict() == {1: 7.0, 2: 3.0, 3: 5.0, 4: 4.0, 5: 3.0}
    assert scores["advised_steps"].to_dict() == {1: 0, 2: 0, 3: 0, 4: 0, 5: 2}
    assert scores["advised_reward"].to_dict() == {1: 0.0, 2: 0.0, 3: 0.0, 4: 0.0, 5: 0.0}
    assert set(scores["episodes"]) == {2}


def test_advice_in_training_under_another_strategy_is_left_out_not_windowed() -> None:
    episodes = _episodes()
    advised = _advised()
    advised = advised[advised["session_id"] != 3]  # no alternating advice past episode 1
    found = comparable(episodes, advised, STRATEGY)
    assert found.first == 2  # learner 4's advice in episode 1
    score = found.scores.set_index("session_id")["score"]
    assert score[5] == pytest.approx(1.0 + (3.0 - 1.0) + (0.0 + 1.0))
    assert found.scores.set_index("session_id")["advised_reward"][5] == 0.0


def test_where_the_advice_falls_per_condition_and_the_differences_named() -> None:
    timing = comparable(_episodes(), _advised(), STRATEGY).timing.set_index("condition")
    assert timing.loc["early", "pretraining_advice"] == 2.0  # 3 and 1 advised steps
    assert timing.loc["early", "training_advice"] == 0.0
    assert timing.loc["alternating", "training_advice"] == 2.0  # 3 and 1
    assert (timing.loc["alternating", "first_advised_episode"],
            timing.loc["alternating", "last_advised_episode"]) == (1, 2)  # fmt: skip
    notes = timing_notes(timing.reset_index())
    assert len(notes) == 3  # every pair differs
    assert "early in pretraining only; alternating in training episodes 1-2" in notes[0] or (
        "alternating in training episodes 1-2; early in pretraining only" in notes[0]
    )
    same = timing.reset_index()
    same = same[same["condition"] != "importance"].assign(
        pretraining_advice=2.0, training_advice=0.0, first_advised_episode=None,
        last_advised_episode=None,
    )  # fmt: skip
    assert timing_notes(same) == [], "advice in pretraining for both: no difference"


def test_each_strategy_says_which_rule_it_follows() -> None:
    assert "window starts after the last advised episode" in rule("alternating")
    assert "left out" in rule("importance") and "left out" in rule("mistake_correcting")
    assert "pretraining" in rule("early")
    assert "left out" in rule("a researcher's own")


def test_the_section_tests_between_conditions_and_says_no_test_with_one_learner(
    tmp_path: Path,
) -> None:
    found = comparable(_episodes(), _advised(), STRATEGY)
    lines, files = comparable_section(found, STRATEGY, tmp_path, 0.05)
    tests = pd.read_csv(tmp_path / "comparable_tests.csv")
    pairs = tests.set_index(["condition_a", "condition_b"])
    # early 7, 3 against alternating 5, 4: a difference in means of 5 - 4.5
    assert pairs.loc[("early", "alternating"), "estimate"] == pytest.approx(0.5)
    assert pairs["no_test"].notna().sum() == 2, "importance has one learner"
    assert tmp_path / "comparable_curves.png" in files
    text = "\n".join(lines)
    assert "training episodes 3-4" in text and "differ in when the advice falls" in text
