"""A task defined only inside the tests: a dot on a line of 40 pixels, moved by one of
five steps (-2 to +2) toward a target column; 40x40 images, `is_success` on reaching it."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from tasks import Task, TaskAction, TaskOptions, task_factory

SIDE = 40
STEPS = (-2, -1, 0, 1, 2)


class LineEnv(gym.Env[np.ndarray, int]):
    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012 (Gymnasium's own attribute)

    def __init__(self, max_episode_steps: int) -> None:
        self.limit = max_episode_steps
        self.observation_space = gym.spaces.Box(0, 255, (SIDE, SIDE, 3), np.uint8)
        self.action_space = gym.spaces.Discrete(len(STEPS))  # type: ignore[assignment]
        self.render_mode = "rgb_array"

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.at, self.target = (int(x) for x in self.np_random.integers(SIDE, size=2))
        self.steps = 0
        return self.render(), self._info()

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.at = int(np.clip(self.at + STEPS[int(action)], 0, SIDE - 1))
        self.steps += 1
        done = self.at == self.target
        truncated = not done and self.steps >= self.limit
        return self.render(), 1.0 if done else -0.01, done, truncated, self._info()

    def render(self) -> np.ndarray:
        image = np.zeros((SIDE, SIDE, 3), np.uint8)
        image[:, self.target, 1] = 255
        image[SIDE // 2, self.at, 0] = 255
        return image

    def _info(self) -> dict[str, Any]:
        gap = self.target - self.at
        return {"correct_action": int(np.clip(gap, -2, 2)) + 2, "is_success": gap == 0}


def _make_env(options: TaskOptions, max_episode_steps: int, record_motion: bool) -> gym.Env:
    return LineEnv(max_episode_steps)


@task_factory
def line_task() -> Task:
    return Task(
        name="line",
        title="Reach the line",
        make_env=_make_env,
        actions=tuple(TaskAction(f"step {s:+d}") for s in STEPS),
        goal="Bring the red dot onto the green line.",
    )
