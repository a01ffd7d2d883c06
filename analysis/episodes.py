"""The episode table every analysis reads, and its validation.

The analysis never touches the database: callers (the `ideeprl report` command, the
dashboard, a researcher with an exported CSV) hand it one tidy DataFrame, one row per
(session, episode). Validation happens here, once, so that the statistics can assume a
rectangular table: every agent has the episodes 1..N, the same N for all.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Protocol

import numpy as np
import pandas as pd

from analysis.markdown import some

REQUIRED_COLUMNS: tuple[str, ...] = ("session_id", "method", "episode", "collected_reward")
"""Columns every episode table must have."""

OPTIONAL_COLUMNS: tuple[str, ...] = (
    "label",
    "seed",
    "steps",
    "placed_correct",
    "misplaced",
    "lost",
    "success",
    "epsilon",
)
"""Columns used when present: `label` names an agent in figures (derived when absent),
`epsilon` draws the exploration schedule, the counts are summarised per method."""

PLACEMENTS: tuple[str, ...] = ("placed_correct", "misplaced", "lost")
"""The sorting robot's outcomes of an episode (a report of another task leaves them out)."""
OUTCOME_COLUMNS: tuple[str, ...] = ("steps", *PLACEMENTS)

EPISODE_TABLE_COLUMNS: tuple[str, ...] = (
    "session_id",
    "method",
    "seed",
    "episode",
    "collected_reward",
    *OUTCOME_COLUMNS,
    "success",
    "epsilon",
)
"""The table the platform gives the analysis (from its database, or from an export);
`label` is left to the analysis (DeepRL1, agent-IDeepRL1, ... by method and seed, so
agents on the same seed share a number across methods)."""
"""Per-episode counts that the per-method table averages when present."""

METHOD_ORDER: tuple[str, ...] = (
    "autonomous", "agent", "human", "fitted", "oracle", "random", "procedure", "sb3-dqn",
)  # fmt: skip
"""The order methods appear in tables and legends; other methods follow alphabetically."""

METHOD_NAMES: dict[str, str] = {
    "autonomous": "autonomous DeepRL",
    "agent": "agent-IDeepRL",
    "human": "human-IDeepRL",
    "fitted": "fitted-IDeepRL",
    "oracle": "oracle-IDeepRL",
    "random": "random-IDeepRL",
    "procedure": "procedure control",
    "sb3-dqn": "SB3 DQN",
    "oracle-evaluative": "oracle evaluative feedback",
    "agent-evaluative": "agent evaluative feedback",
    "oracle-evaluative-rating_model": "oracle evaluative feedback, rating model",
    "procedure-evaluative": "procedure control of evaluative feedback",
    "procedure-evaluative-rating_model": "procedure control of evaluative feedback, rating model",
    "agent-evaluative-rating_model": "agent evaluative feedback, rating model",
    "fitted-evaluative": "fitted evaluative feedback",
    "fitted-evaluative-rating_model": "fitted evaluative feedback, rating model",
}
"""Display names in the paper's words (and Stable-Baselines3's DQN, the independent
baseline)."""

_LABEL_STEMS: dict[str, str] = {"autonomous": "DeepRL"}

CONTRACT = (
    "one row per (session, episode) with columns session_id, method, episode (1..N), "
    "collected_reward (the episode's summed reward); optional: " + ", ".join(OPTIONAL_COLUMNS)
)


PYTHON_LENGTH = "n_episodes={n}"
"""How the Python API (`validate_episodes`, `write_report`) is told to keep the first N
episodes: the default wording of `EpisodeTableError.worded`."""


class EpisodeTableError(ValueError):
    """The episode table breaks the contract; the message says what to change.

    Where the fix is a number of episodes to keep (`n_episodes`), the message names it in
    the Python API's terms (`n_episodes=9`); `worded` names it in a caller's own (the
    command line's `--n-episodes 9`, the REST body's `n_episodes`)."""

    def __init__(self, message: str, n_episodes: int | None = None) -> None:
        self.text = message
        """The message, `{n_episodes}` where it names the number of episodes to keep."""
        self.n_episodes = n_episodes
        """That number (None: the message names none)."""
        super().__init__(self.worded(PYTHON_LENGTH))

    def worded(self, length: str) -> str:
        """The message, its number of episodes to keep in the caller's terms: `length`, a
        template with `{n}` (e.g. "`--n-episodes {n}`")."""
        if self.n_episodes is None:
            return self.text
        return self.text.replace("{n_episodes}", length.format(n=self.n_episodes))


def arm(method: str, feedback: str = "advice", feedback_method: str = "shaping") -> str:
    """What a report compares a run as: its method, and for evaluative feedback (the
    paper's other strategy) its method with `-evaluative` (and `-rating_model` where a
    model of the ratings shapes the steps not judged), so that advice and evaluation by
    the same advisor, and the two ways of learning from a judgement, are apart, never one
    mean."""
    if feedback != "evaluative":
        return method
    suffix = "" if feedback_method == "shaping" else f"-{feedback_method}"
    return f"{method}-evaluative{suffix}"


class Armed(Protocol):
    """A run as `arm` reads it (a `RunSpec`)."""

    @property
    def method(self) -> str: ...
    @property
    def feedback(self) -> str: ...
    @property
    def feedback_method(self) -> str: ...


def arm_of(run: Armed) -> str:
    """The arm a run is compared in (`arm`)."""
    return arm(run.method, run.feedback, run.feedback_method)


def method_name(method: str) -> str:
    """The display name of a method, e.g. "agent" -> "agent-IDeepRL"."""
    return METHOD_NAMES.get(method, method)


def order_methods(methods: Iterable[str], baseline: str | None = None) -> list[str]:
    """Methods in display order: the baseline first, then `METHOD_ORDER`, then the rest."""
    unique = set(methods)
    known = [m for m in METHOD_ORDER if m in unique]
    ordered = known + sorted(unique - set(known))
    if baseline in unique:
        ordered.remove(baseline)
        ordered.insert(0, baseline)
    return ordered


def natural_key(label: str) -> tuple[object, ...]:
    """Sort key that puts "human-IDeepRL2" before "human-IDeepRL10"."""
    parts = re.split(r"(\d+)", label)
    return tuple(int(p) if i % 2 else p for i, p in enumerate(parts))


def _fail(problem: str, fix: str, n_episodes: int | None = None) -> EpisodeTableError:
    """`fix` may hold `{n_episodes}`: the number `n_episodes` in the caller's terms."""
    return EpisodeTableError(f"{problem}. {fix}", n_episodes)


def _one_per_session(table: pd.DataFrame, column: str) -> None:
    counts = table.groupby("session_id", sort=False)[column].nunique(dropna=False)
    mixed = counts[counts > 1].index
    if len(mixed):
        raise _fail(
            f"column {column!r} changes within sessions {some(mixed)}",
            f"A session is one agent: give every row of a session the same {column}",
        )


def _derive_labels(table: pd.DataFrame) -> pd.Series:
    """Labels like the paper's "human-IDeepRL6": the method's name and a 1-based number."""
    sessions = table.drop_duplicates("session_id")
    key = ["method", "seed", "session_id"] if "seed" in sessions else ["method", "session_id"]
    sessions = sessions.sort_values(key, kind="stable")
    number = sessions.groupby("method", sort=False).cumcount() + 1
    stems = sessions["method"].map(lambda m: _LABEL_STEMS.get(m, method_name(m)))
    derived = dict(zip(sessions["session_id"], stems + number.astype(str), strict=True))
    return table["session_id"].map(derived)


def validate_episodes(episodes: pd.DataFrame, *, n_episodes: int | None = None) -> pd.DataFrame:
    """Check the episode table against the contract and return a clean, sorted copy.

    `n_episodes` keeps only the first N episodes of every agent: the way to compare
    agents whose runs have different lengths (an unfinished session, a longer run).
    The copy has a `label` for every row, `episode` as int, `collected_reward` as float,
    and is sorted by method (see `order_methods`), label and episode. Raises
    `EpisodeTableError` with what is wrong and what to do.
    """
    if not isinstance(episodes, pd.DataFrame):
        raise _fail(
            f"expected a pandas DataFrame of episodes, got {type(episodes).__name__}",
            f"Pass {CONTRACT}",
        )
    missing = [c for c in REQUIRED_COLUMNS if c not in episodes.columns]
    if missing:
        raise _fail(
            f"the episode table lacks column(s) {', '.join(missing)} "
            f"(it has {', '.join(map(str, episodes.columns)) or 'none'})",
            f"Pass {CONTRACT}",
        )
    if episodes.empty:
        raise _fail("the episode table has no rows", "Select sessions that have run episodes")
    table = episodes.copy()
    if table["session_id"].isna().any() or table["method"].isna().any():
        raise _fail("some rows have no session_id or no method", "Drop those rows or fill them in")
    table["method"] = table["method"].astype(str)

    episode = pd.to_numeric(table["episode"], errors="coerce")
    bad = table.loc[episode.isna() | (episode < 1) | (episode % 1 != 0), "episode"]
    if len(bad):
        raise _fail(
            f"episode must be a whole number from 1, found {some(bad.unique())}",
            "Number each session's episodes 1, 2, ..., N",
        )
    table["episode"] = episode.astype(np.int64)

    reward = pd.to_numeric(table["collected_reward"], errors="coerce")
    bad_rows = table.loc[~np.isfinite(reward.to_numpy(dtype=float))]
    if len(bad_rows):
        where = some(f"{s}/{e}" for s, e in zip(bad_rows.session_id, bad_rows.episode, strict=True))
        raise _fail(
            f"collected_reward is missing or not a finite number at session/episode {where}",
            "Drop those episodes (and use n_episodes= to keep agents equal) or fix the values",
        )
    table["collected_reward"] = reward.astype(float)

    duplicated = table.duplicated(["session_id", "episode"], keep=False)
    if duplicated.any():
        rows = table.loc[duplicated]
        where = some(
            sorted({f"{s}/{e}" for s, e in zip(rows.session_id, rows.episode, strict=True)})
        )
        raise _fail(
            f"session/episode pairs appear more than once: {where}",
            "Keep one row per (session, episode); check that two studies were not concatenated",
        )

    _one_per_session(table, "method")
    if "seed" in table:
        _one_per_session(table, "seed")
    if "label" in table:
        _one_per_session(table, "label")
        derived = _derive_labels(table)
        table["label"] = table["label"].astype("string").fillna(derived).astype(str)
    else:
        table["label"] = _derive_labels(table)
    labels = table.drop_duplicates("session_id")
    shared = labels[labels.duplicated("label", keep=False)]
    if len(shared):
        names = some(sorted(shared["label"].unique()))
        raise _fail(
            f"label(s) {names} name more than one session",
            "Give each session its own label, or drop the label column to derive them",
        )

    counts = table.groupby("session_id", sort=False)["episode"].agg(["count", "max"])
    gaps = counts[counts["count"] != counts["max"]].index
    if len(gaps):
        raise _fail(
            f"sessions {some(gaps)} skip episodes (their episodes are not 1..N)",
            "Export every episode of those sessions, or drop them",
        )
    if n_episodes is not None:
        if n_episodes < 1:
            raise _fail(f"n_episodes must be at least 1, got {n_episodes}", "Pass N >= 1")
        short = counts[counts["count"] < n_episodes]
        if len(short):
            raise _fail(
                f"sessions {some(short.index)} have only "
                f"{some(sorted(short['count'].unique()))} episodes, fewer than the "
                f"{n_episodes} asked for",
                "Pass {n_episodes} or less, or drop those sessions.",
                int(counts["count"].min()),
            )
        table = table[table["episode"] <= n_episodes]
    elif counts["count"].nunique() > 1:
        sizes = counts.groupby("count").size().sort_index()
        summary = "; ".join(f"{n} session(s) with {k} episodes" for k, n in sizes.items())
        fewest = int(sizes.index.min())
        shortest = some(counts[counts["count"] == fewest].index)
        raise _fail(
            f"agents have unequal numbers of episodes ({summary}; "
            f"the shortest: session(s) {shortest})",
            "R_T and the curves compare equal runs: pass {n_episodes} to keep the first "
            "episodes of every agent, or drop the unfinished sessions.",
            fewest,
        )

    method_rank = {m: i for i, m in enumerate(order_methods(table["method"]))}
    label_rank = {x: i for i, x in enumerate(sorted(table["label"].unique(), key=natural_key))}
    table = table.assign(_m=table["method"].map(method_rank), _l=table["label"].map(label_rank))
    table = table.sort_values(["_m", "_l", "episode"]).drop(columns=["_m", "_l"])
    return table.reset_index(drop=True)


def agents_of(episodes: pd.DataFrame) -> pd.DataFrame:
    """One row per agent of a validated table: session_id, label, method (and seed)."""
    columns = ["session_id", "label", "method"] + (["seed"] if "seed" in episodes else [])
    return episodes.drop_duplicates("session_id")[columns].reset_index(drop=True)


def reward_curves(episodes: pd.DataFrame) -> pd.DataFrame:
    """Collected reward per episode, one column per agent label (in table order)."""
    table = validate_episodes(episodes)
    wide = table.pivot(index="episode", columns="label", values="collected_reward")
    return wide[list(agents_of(table)["label"])]
