"""What the learner reports: one record per environment step and one per episode.

The field docstrings are the column dictionary of the exports
(`learner.docstrings.field_docstrings`).

Numbering. Global steps count every environment step of a run from 1: pretraining is
steps 1..pretraining_steps, training follows. Episodes are numbered from 1 within their
stage: pretraining episodes (`stage` "pretrain") and training episodes (`stage` "train",
1..`episodes`) each start at 1, so a step's `episode` refers to the pretraining episode of
that number when its stage is "pretrain", and to the training episode when it is "train".
Advice is an action source (`action_source` "advisor"), never a stage. Pretraining
episodes are recorded for completeness (they show the advisor's effect on the memory) but
are not among the training episodes whose collected reward the paper reports; the last
one is cut when pretraining ends.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

Stage = Literal["pretrain", "train"]
"""The part of a run: `pretrain` (Algorithm 1: the memory is filled, random or advised
actions) or `train` (Algorithm 2)."""
STAGES: tuple[Stage, ...] = ("pretrain", "train")
TRAINING: Stage = "train"
"""The stage whose episodes are the run's results (a report compares them)."""
OLD_STAGES = {"pretraining": "pretrain", "training": "train", "advice": "pretrain"}
"""Older spellings of a stage (checkpoints, step rows and exports written before one word
was kept): `advice` was an advised pretraining step."""


def stage_of(text: str) -> Stage:
    """A stage from its spelling, old spellings included."""
    return OLD_STAGES.get(text, text)  # type: ignore[return-value]


ActionSource = Literal["random", "advisor", "greedy", "exploration"]
Outcome = Literal["placed", "misplaced", "lost", "none"]


@dataclass(frozen=True)
class StepRecord:
    """One environment step."""

    global_step: int
    """Step number in the whole run, from 1 (pretraining, then training)."""
    stage: Stage
    """`pretrain` (pretraining stage: random actions, or advised ones under early advising:
    see `action_source`) or `train` (training stage, advice given during it included)."""
    episode: int
    """Episode number within the stage, from 1: a pretraining episode for stage `pretrain`,
    a training episode for `train`."""
    episode_step: int
    """Step number within the episode, from 1."""
    action: int
    """The action executed, its index in the run's task's actions (the sorting robot's: 0
    grab, 1 move right, 2 move left, 3 drop; the export's q_ columns name each task's)."""
    action_source: ActionSource
    """Who chose the executed action: `random` (pretraining), `advisor` (advice is policy
    shaping: the advised action is executed), `greedy` (the learner's best action) or
    `exploration` (epsilon-greedy's random action)."""
    greedy_action: int
    """The learner's own greedy choice before this step (argmax of its Q-values)."""
    q_grab: float | None
    """The learner's Q-value of action 0 in the observed state (the sorting robot's grab);
    for a task with four actions its actions 0-3 fill these four fields, else they are
    empty and `q_values` holds them. The export and `ideeprl train`'s steps.csv name them
    by the task's actions instead (`named_q`: q_grab, q_move_right, ... for the sorting
    robot; q_up, q_right, ... in the grid world)."""
    q_move_right: float | None
    """The learner's Q-value of action 1 (the sorting robot's move right)."""
    q_move_left: float | None
    """The learner's Q-value of action 2 (the sorting robot's move left)."""
    q_drop: float | None
    """The learner's Q-value of action 3 (the sorting robot's drop)."""
    q_values: str | None
    """A task without four actions: the learner's Q-values in action order, as a JSON list
    (empty for four actions: the four fields above hold them)."""
    advised_action: int | None
    """The advisor's action when advice was given at this step, else empty."""
    advice_remaining: int
    """Advice budget left after this step (0 without an advisor)."""
    reward: float
    """Reward of this step."""
    terminated: bool
    """The episode ended in a terminal state (task complete, or a misplacement)."""
    truncated: bool
    """The episode was cut without a terminal state: the step limit, or the end of
    pretraining."""
    outcome: Outcome
    """What the step did to the objects: `placed` (one where it belongs), `misplaced` (one
    on the wrong side), `lost` (one knocked off the center table) or `none`. Rescoring
    under another reward scheme keeps the rewards of placements only (empty in logs
    recorded before it was kept, until `ideeprl outcomes` replays them)."""
    observation_hash: str
    """What the learner saw when it chose this step's action: the first 16 hex digits of
    the BLAKE2b hash of the uint8 image, or of a vector task's float32 vector
    (`observation_hash`). Equal hashes, equal observations: a replay compares its steps
    with the original's by them (empty in rows recorded before it was kept)."""
    epsilon: float
    """Exploration rate used to choose this step's action."""
    loss: float | None
    """Loss of the update made after this step (training stage only)."""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class EpisodeRecord:
    """One episode, pretraining or training."""

    stage: Stage
    """`pretrain` or `train`; the paper's curves and R_T use the `train` episodes only."""
    episode: int
    """Episode number within its stage, from 1."""
    collected_reward: float
    """Sum of the episode's rewards (the paper's collected reward; 3.0 at best)."""
    steps: int
    """Steps in the episode."""
    placed_correct: int
    """Objects placed on the correct table."""
    misplaced: int
    """Objects placed on the wrong table (a misplacement ends the episode)."""
    lost: int
    """Objects knocked off a table."""
    success: bool
    """The episode ended with the task complete (terminated without a misplacement)."""
    terminated: bool
    """The episode ended in a terminal state."""
    truncated: bool
    """The episode was cut: the step limit, or the end of pretraining."""
    advised_steps: int
    """Steps whose action came from the advisor."""
    epsilon: float
    """Exploration rate at the end of the episode."""
    mean_loss: float | None
    """Mean update loss over the episode's steps (training episodes only)."""
    first_global_step: int
    """Global step of the episode's first step."""
    last_global_step: int
    """Global step of the episode's last step."""
    reset_seed: int | None = None
    """Seed the environment was reset with for this episode (drawn from the trainer's
    RNG): the scene, and with the episode's actions every step, can be replayed from it."""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


STORED_Q = ("q_grab", "q_move_right", "q_move_left", "q_drop", "q_values")
"""A `StepRecord`'s Q-value fields, by position: the first four hold a task's with four
actions, `q_values` any other number. Files for people (the study export, `ideeprl train`'s
steps.csv) name them by the task's actions instead: `named_q`."""


def named_q(step: Mapping[str, Any], names: Sequence[str]) -> dict[str, Any]:
    """A step's Q-values (a `StepRecord`'s, or a row stored from one) as one `q_<name>`
    entry per action of its task, `names` in action order (`tasks.Task.action_names`);
    `ValueError` where the step holds another number of them."""
    listed = step.get("q_values")
    values = [step.get(c) for c in STORED_Q[:4]] if listed in (None, "") else json.loads(listed)
    if len(values) != len(names):
        raise ValueError(f"the step holds {len(values)} Q-values for {len(names)} actions")
    return {f"q_{name}": value for name, value in zip(names, values, strict=True)}


def observation_hash(obs: Any) -> str:
    """A short fingerprint of an observation (an image's uint8 bytes, a vector's float32
    ones): what a replay compares, step by step and advice by advice, without storing every
    image."""
    import numpy as np

    array = np.asarray(obs)
    vector = array.ndim == 1 and np.issubdtype(array.dtype, np.floating)
    data = np.ascontiguousarray(array, dtype=np.float32 if vector else np.uint8)
    return hashlib.blake2b(data.tobytes(), digest_size=8).hexdigest()
