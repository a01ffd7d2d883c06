"""Learning outcomes that compare like with like: each learner's score over a window of
training episodes every compared condition shares, without the reward its advised steps
earned.

R_T sums every training episode's collected reward. Where a strategy's advice falls in
training episodes, R_T counts what the advised steps earned (the advisor's choice, not the
learner's) beside what the learner learnt; where it falls in pretraining (the random
practice R_T leaves out), R_T counts none of it. So two conditions that differ only in
when the advice falls are not compared like with like on R_T. Here, for each strategy:

- `early` (advice in the last pretraining steps): nothing to leave out; every training
  episode of the window counts as it is.
- `alternating` (advice every few steps from the first training step until the budget is
  spent, so in the first training episodes): the window starts after the last advised
  episode of every compared learner of such a strategy.
- `importance`, `mistake_correcting` and any other (advice wherever the advisor's
  Q-values or the learner's mistakes say, possibly in any episode): the advised steps'
  rewards are left out of the score and reported on their own.

One rule covers the three: the window is shared (from after the last advised episode of
the `alternating` learners to the last episode every learner has), and within it any
advised step's reward is left out. The timing table says, per condition, where the advice
fell, and `timing_notes` names each difference between conditions.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from itertools import combinations

import pandas as pd

WINDOW_AFTER = frozenset({"alternating"})
"""Strategies whose advice falls in the first training episodes: the shared window starts
after their last advised episode."""
RULES = {
    "early": "its advice falls in pretraining, which R_T does not count: every training "
    "episode of the window counts as it is",
    "alternating": "its advice falls in the first training episodes: the window starts "
    "after the last advised episode",
    "importance": "its advice may fall in any training episode: the advised steps' rewards "
    "are left out of the score and reported on their own",
    "mistake_correcting": "its advice may fall in any training episode: the advised steps' "
    "rewards are left out of the score and reported on their own",
}
"""What the score does for each strategy, in the report's words."""
OTHER_RULE = "the advised steps' rewards are left out of the score and reported on their own"
SCORE_COLUMNS = [
    "session_id", "condition", "strategy", "episodes", "score", "advised_steps",
    "advised_reward",
]  # fmt: skip
TIMING_COLUMNS = [
    "condition", "learners", "pretraining_advice", "training_advice",
    "first_advised_episode", "last_advised_episode",
]  # fmt: skip


@dataclass(frozen=True)
class Comparable:
    """The shared window and each learner's score over it."""

    first: int
    """The window's first training episode (from 1)."""
    last: int
    """Its last (the last every compared learner has); below `first`: no window."""
    scores: pd.DataFrame
    """One row per learner (`SCORE_COLUMNS`): its score over the window (collected reward
    less the advised steps' rewards), the advised steps in the window and what they earned."""
    curves: pd.DataFrame
    """session_id, condition, episode, score: each learner's episodes of the window."""
    timing: pd.DataFrame
    """Per condition (`TIMING_COLUMNS`): learners, advised steps in pretraining and in
    training (means per learner), the first and last training episode advised (over the
    condition's learners; NaN without any)."""

    @property
    def empty(self) -> bool:
        return self.last < self.first


def rule(strategy: str | None) -> str:
    """What the score does for a learner of this strategy (None: no advice)."""
    if strategy is None:
        return "no advice: every training episode of the window counts as it is"
    return RULES.get(strategy, OTHER_RULE)


def comparable(
    episodes: pd.DataFrame, advised: pd.DataFrame, strategies: Mapping[int, str | None]
) -> Comparable:
    """The scores of the learners in `episodes` (session_id, method: the condition,
    episode, collected_reward; training episodes) given their `advised` steps (session_id,
    stage, episode, reward; every stage) and each session's strategy (None: no advice)."""
    ids = list(dict.fromkeys(episodes["session_id"]))
    advised = advised[advised["session_id"].isin(ids)]
    training = advised[advised["stage"] == "train"]
    condition = episodes.groupby("session_id")["method"].first()
    after = [i for i in ids if strategies.get(i) in WINDOW_AFTER]
    last_advised = training.groupby("session_id")["episode"].max()
    first = 1 + int(max((last_advised.get(i, 0) for i in after), default=0))
    last = int(episodes.groupby("session_id")["episode"].max().min()) if ids else 0
    window = episodes[episodes["episode"].between(first, last)]
    in_window = training[training["episode"].between(first, last)]
    taken = in_window.groupby(["session_id", "episode"])["reward"].sum()
    keys = pd.MultiIndex.from_frame(window[["session_id", "episode"]])
    less = taken.reindex(keys).fillna(0.0).to_numpy()
    curves = window.assign(
        condition=window["method"], score=window["collected_reward"].to_numpy() - less
    )[["session_id", "condition", "episode", "score"]].reset_index(drop=True)
    rows = []
    for i in ids:
        mine = in_window[in_window["session_id"] == i]
        rows.append(
            {
                "session_id": i,
                "condition": condition[i],
                "strategy": strategies.get(i) or "none",
                "episodes": max(last - first + 1, 0),
                "score": float(curves.loc[curves["session_id"] == i, "score"].sum()),
                "advised_steps": len(mine),
                "advised_reward": float(mine["reward"].sum()),
            }
        )
    scores = pd.DataFrame(rows, columns=SCORE_COLUMNS)
    return Comparable(first, last, scores, curves, _timing(ids, condition, advised))


def _timing(ids: list[int], condition: pd.Series, advised: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for name in dict.fromkeys(condition[ids]):
        members = [i for i in ids if condition[i] == name]
        mine = advised[advised["session_id"].isin(members)]
        training = mine[mine["stage"] == "train"]
        rows.append(
            {
                "condition": name,
                "learners": len(members),
                "pretraining_advice": (mine["stage"] != "train").sum() / len(members),
                "training_advice": len(training) / len(members),
                "first_advised_episode": training["episode"].min() if len(training) else None,
                "last_advised_episode": training["episode"].max() if len(training) else None,
            }
        )
    return pd.DataFrame(rows, columns=TIMING_COLUMNS)


def timing_notes(timing: pd.DataFrame) -> list[str]:
    """One sentence per pair of conditions whose advice falls at different times: in
    pretraining only against in training episodes, or in different training episodes."""
    notes = []
    rows = {row["condition"]: row for _, row in timing.iterrows()}
    for a, b in combinations(rows, 2):
        where_a, where_b = _where(rows[a]), _where(rows[b])
        if where_a != where_b:
            notes.append(
                f"The conditions {a} and {b} differ in when the advice falls: {a} {where_a}; "
                f"{b} {where_b}. R_T over every training episode counts the reward of advised "
                "training steps; the comparable score does not."
            )
    return notes


def _where(row: pd.Series) -> str:
    if not row["training_advice"]:
        return "in pretraining only" if row["pretraining_advice"] else "nowhere (no advice)"
    place = (
        f"in training episodes {int(row['first_advised_episode'])}-"
        f"{int(row['last_advised_episode'])}"
    )
    if row["pretraining_advice"]:
        place = f"in pretraining and {place}"
    return place
