"""The paper's task: a robot arm sorting red and blue objects onto two tables (`sim`).

Its options are the run's own sorting fields (`motion`, `sort_rule`, `scenario`), which
runs have always carried; `RunSpec` hands them here."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym

from sim.actions import ACTION_NAMES
from sim.rewards import REWARD_SCHEMES, rescore
from sim.rules import oracle_action
from sim.scenario import ScenarioOptions
from tasks import (
    GymInfo,
    OptionValue,
    RecordedEpisode,
    RewardSchemes,
    Situations,
    Task,
    TaskAction,
    TaskOptions,
    task_factory,
)

TEXTS = Path(__file__).with_name("texts")
"""The participant pages' texts for this task (the robot, its tables and its four actions)."""

KEYS = ("g", "ArrowRight", "ArrowLeft", "d")
"""The advice page's keys, in action order (grab, move right, move left, drop)."""

OPTIONS: dict[str, OptionValue] = {
    "motion": "fast",
    "sort_rule": "color",
    **ScenarioOptions().to_dict(),
}

ABOUT = "A placement keeps its reward, every other step costs what the scheme says (`sim.rewards`)."
"""How its runs are rescored, for the report."""

STATIONS = ("center", "left", "right")
HELD = ("nothing", "red", "blue")
"""What the arm holds, as a situation knows it: nothing, or the held object's colour."""


def situation(info: GymInfo) -> tuple[str, str]:
    """(station, held) of the environment's ground truth: `("center", "blue")`. Nine
    situations stay estimable from about 100 advice a person."""
    return str(info["station"]), str(info.get("held_color") or "") or "nothing"


def _make_env(
    options: TaskOptions, max_episode_steps: int, record_motion: bool
) -> gym.Env[Any, Any]:
    from sim.env import SortingEnv  # PyBullet: imported when an environment is made

    given: dict[str, Any] = dict(options)  # checked by the run: motion, sort_rule, scenario
    return SortingEnv(max_episode_steps=max_episode_steps, record_motion=record_motion, **given)


def _correct(info: GymInfo, options: TaskOptions) -> int | None:
    rule = options["sort_rule"]
    assert isinstance(rule, str | dict), "checked by the run"
    return oracle_action(info, rule)


def _rescore(
    episode: RecordedEpisode, scheme: str, to_scheme: str, options: TaskOptions
) -> list[float]:
    """A placement keeps its reward, every other step costs what `to_scheme` says
    (`sim.rewards.rescore`)."""
    outcomes = None if episode.outcomes is None else list[str | None](episode.outcomes)
    return rescore(list(episode.rewards), list(episode.terminated), scheme, to_scheme, outcomes)


@task_factory
def sorting_task() -> Task:
    return Task(
        name="sorting",
        title="Sorting objects",
        make_env=_make_env,
        actions=tuple(TaskAction(w, k) for w, k in zip(ACTION_NAMES, KEYS, strict=True)),
        goal="Sort the objects on the center table onto the side tables by their rule.",
        options=OPTIONS,
        correct_action=_correct,
        good_reward=2.5,
        live_view=True,
        agent="robot",
        outcomes=("placed", "misplaced", "lost"),
        situations=Situations(situation, STATIONS, HELD),
        reward_schemes=RewardSchemes(REWARD_SCHEMES, _rescore, "reward_scheme", ABOUT),
        texts={f.stem: f.read_text() for f in sorted(TEXTS.glob("*.txt"))},
    )
