"""The episode table contract: what is accepted, and what each error tells the user."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis import EpisodeTableError, reward_curves, validate_episodes
from tests.analysis.helpers import HAND_CASE, episodes_from_curves


def test_a_valid_table_comes_back_sorted_and_typed() -> None:
    table = episodes_from_curves(HAND_CASE).sample(frac=1.0, random_state=3)
    table["episode"] = table["episode"].astype(float)
    clean = validate_episodes(table)
    assert list(clean["method"].unique()) == ["autonomous", "agent", "human"]
    assert clean["episode"].dtype == np.int64
    assert list(clean.loc[clean["label"] == "DeepRL2", "collected_reward"]) == [2.0, 1.0, 2.0]
    assert len(clean) == len(table)


@pytest.mark.parametrize("column", ["session_id", "method", "episode", "collected_reward"])
def test_a_missing_column_is_named_with_the_contract(column: str) -> None:
    table = episodes_from_curves(HAND_CASE).drop(columns=[column])
    with pytest.raises(EpisodeTableError, match=f"lacks column\\(s\\) {column}.*Pass one row per"):
        validate_episodes(table)


def test_not_a_dataframe_or_empty_is_refused() -> None:
    with pytest.raises(EpisodeTableError, match="expected a pandas DataFrame"):
        validate_episodes([{"session_id": 1}])  # type: ignore[arg-type]
    empty = episodes_from_curves(HAND_CASE).iloc[:0]
    with pytest.raises(EpisodeTableError, match="no rows"):
        validate_episodes(empty)


def test_unequal_episode_counts_say_how_to_cut_them() -> None:
    table = episodes_from_curves({"a": ("autonomous", [1.0, 2.0, 3.0]), "b": ("agent", [1.0, 2.0])})
    with pytest.raises(EpisodeTableError) as error:
        validate_episodes(table)
    message = str(error.value)
    assert "unequal numbers of episodes" in message
    assert "1 session(s) with 2 episodes; 1 session(s) with 3 episodes" in message
    assert "the shortest: session(s) 2" in message
    assert "n_episodes=2" in message
    cut = validate_episodes(table, n_episodes=2)
    assert cut.groupby("label")["episode"].max().to_dict() == {"a": 2, "b": 2}
    assert list(cut.loc[cut["label"] == "a", "collected_reward"]) == [1.0, 2.0]


def test_asking_for_more_episodes_than_an_agent_has_is_refused() -> None:
    table = episodes_from_curves({"a": ("autonomous", [1.0, 2.0]), "b": ("agent", [1.0, 2.0])})
    with pytest.raises(EpisodeTableError, match=r"have only 2 episodes.*n_episodes=2 or less"):
        validate_episodes(table, n_episodes=3)


def test_duplicated_and_missing_episodes_are_refused() -> None:
    table = episodes_from_curves(HAND_CASE)
    doubled = pd.concat([table, table.iloc[[0]]])
    with pytest.raises(EpisodeTableError, match="more than once: 1/1"):
        validate_episodes(doubled)
    gap = table[~((table["session_id"] == 2) & (table["episode"] == 2))]
    with pytest.raises(EpisodeTableError, match="sessions 2 skip episodes"):
        validate_episodes(gap)


@pytest.mark.parametrize("bad", [0, 1.5, "first"])
def test_episode_numbers_must_be_whole_from_one(bad: object) -> None:
    table = episodes_from_curves(HAND_CASE).astype({"episode": object})
    table.loc[0, "episode"] = bad
    with pytest.raises(EpisodeTableError, match="whole number from 1"):
        validate_episodes(table)


@pytest.mark.parametrize("bad", [np.nan, np.inf, "lots"])
def test_a_reward_that_is_not_a_number_is_located(bad: object) -> None:
    table = episodes_from_curves(HAND_CASE).astype({"collected_reward": object})
    table.loc[(table["session_id"] == 3) & (table["episode"] == 2), "collected_reward"] = bad
    with pytest.raises(EpisodeTableError, match="session/episode 3/2"):
        validate_episodes(table)


def test_a_session_is_one_agent_of_one_method_with_one_label() -> None:
    table = episodes_from_curves(HAND_CASE)
    mixed = table.copy()
    mixed.loc[mixed.index[1], "method"] = "human"
    with pytest.raises(EpisodeTableError, match="'method' changes within sessions 1"):
        validate_episodes(mixed)
    shared = table.copy()
    shared.loc[shared["label"] == "DeepRL2", "label"] = "DeepRL1"
    with pytest.raises(EpisodeTableError, match="DeepRL1 name more than one session"):
        validate_episodes(shared)


def test_labels_are_derived_in_the_papers_style_when_absent() -> None:
    table = episodes_from_curves(HAND_CASE).drop(columns=["label"])
    table["seed"] = table["session_id"].map({1: 20, 2: 10, 3: 5, 4: 7, 5: 1})
    clean = validate_episodes(table)
    labels = clean.drop_duplicates("session_id").set_index("session_id")["label"].to_dict()
    # numbered within a method by seed: session 2 has the smaller autonomous seed
    assert labels == {
        2: "DeepRL1",
        1: "DeepRL2",
        3: "agent-IDeepRL1",
        4: "agent-IDeepRL2",
        5: "human-IDeepRL1",
    }


def test_agents_are_in_method_then_natural_label_order() -> None:
    curves = {f"human-IDeepRL{i}": ("human", [float(i)]) for i in (10, 2, 1)}
    curves["DeepRL1"] = ("autonomous", [0.0])
    wide = reward_curves(episodes_from_curves(curves))
    assert list(wide.columns) == ["DeepRL1", "human-IDeepRL1", "human-IDeepRL2", "human-IDeepRL10"]
    assert list(wide.iloc[0]) == [0.0, 1.0, 2.0, 10.0]
