"""A robot arm reaching a ball: PyBullet's KUKA iiwa moves its hand one step at a time along
the world's axes to a red ball (`tasks.reach.env`), seen live in 3-D by people.

A scene of our own rather than panda-gym's Reach behind a wrapper: panda-gym (last release
2023) drives a continuous end-effector target with physics steps and a goal vector beside
the observation, where this platform's learner wants discrete moves and an image; its Panda
also has 100,000 visual triangles (18 ms a 64x64 frame in TinyRenderer, 3.4 ms for the
iiwa), the arm's weight on every step and on every participant's page.

The oracle's move is the one that brings the hand nearest the ball, in `info`.

Runs are scored `shaped`: each step earns 0.1 a lattice step the hand came nearer the ball
(less where it went away), and reaching it 1 more. Rescored `sparse`: 1 for the step that
reached the ball (the step that ended the episode), nothing otherwise. The shaped reward
cannot be had back from a sparse record: it counts distances the record does not keep.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from tasks import (
    CheckQuestion,
    RecordedEpisode,
    RescoreError,
    RewardSchemes,
    Task,
    TaskAction,
    TaskOptions,
    task_factory,
)
from tasks.reach.moves import CAMERA, KEYS, MOVE_WORDS

OPTIONS: dict[str, Any] = {"max_steps": 50}
"""The task's own step limit for an episode (the run's may be lower)."""


SCHEMES = ("shaped", "sparse")
"""Its reward schemes, the one runs are scored under first."""
ABOUT = "Under sparse, the step that reached the ball earns 1, every other step nothing."
"""How its runs are rescored, for the report."""


def _rescore(
    episode: RecordedEpisode, scheme: str, to_scheme: str, options: TaskOptions
) -> list[float]:
    if scheme == to_scheme:
        return list(episode.rewards)
    if to_scheme == "shaped":
        raise RescoreError(
            "task reach: the shaped reward counts the hand's distance to the ball at every "
            "step, which a record scored sparse does not keep"
        )
    return [1.0 if ended else 0.0 for ended in episode.terminated]


def _make_env(
    options: TaskOptions, max_episode_steps: int, record_motion: bool
) -> gym.Env[Any, Any]:
    from tasks.reach.env import ReachEnv  # PyBullet: imported when an environment is made

    max_steps = options["max_steps"]
    if not (isinstance(max_steps, int) and 1 <= max_steps <= 10_000):
        raise ValueError(f"reach max_steps must be an int from 1 to 10000, got {max_steps!r}")
    return ReachEnv(min(max_steps, max_episode_steps), record_motion)


@task_factory
def reach_task() -> Task:
    return Task(
        name="reach",
        title="Reaching the ball",
        make_env=_make_env,
        actions=tuple(TaskAction(f"move {w}", k) for w, k in zip(MOVE_WORDS, KEYS, strict=True)),
        goal="Bring the robot's hand to the red ball in as few moves as you can.",
        options=OPTIONS,
        good_reward=1.0,
        reward_schemes=RewardSchemes(SCHEMES, _rescore, about=ABOUT),
        live_view=True,
        camera=CAMERA,
        agent="robot",
        check_questions=(
            CheckQuestion(
                "reach_goal",
                "Where should the robot's hand go?",
                ("To the red ball", "To the floor", "Anywhere"),
                "To the red ball",
            ),
            CheckQuestion(
                "reach_moves",
                "What does 'move up' do?",
                (
                    "Lifts the robot's hand one step",
                    "Turns the robot",
                    "Ends the round",
                ),
                "Lifts the robot's hand one step",
            ),
        ),
    )
