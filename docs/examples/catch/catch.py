"""A researcher's own task, from outside the platform's package: catch a falling ball.

A ball falls one row a step from a random column of a 16 x 16 board; the paddle on the
bottom row moves left, stays or moves right. Catching the ball gives +1 and ends the
episode, missing it gives -1. The learner sees the board as a 32 x 32 RGB image (2 pixels
a square); the correct action moves the paddle toward the ball's column.

Run it by naming `catch:catch_task` as a run's task, with this folder importable by the
server and its workers (`PYTHONPATH=docs/examples/catch`); see docs/examples/own-task.md.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from tasks import Task, TaskAction, TaskOptions, task_factory

BOARD = 16
PIXELS = 2
BALL = (230, 60, 40)
PADDLE = (40, 90, 220)


class CatchEnv(gym.Env[np.ndarray, int]):
    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012 (Gymnasium's own attribute)

    def __init__(self, paddle_width: int = 3, max_episode_steps: int = 250) -> None:
        self.width = paddle_width
        self.limit = max_episode_steps
        side = BOARD * PIXELS
        self.observation_space = gym.spaces.Box(0, 255, (side, side, 3), np.uint8)
        self.action_space = gym.spaces.Discrete(3)  # type: ignore[assignment]
        self.render_mode = "rgb_array"

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.ball = [0, int(self.np_random.integers(BOARD))]  # row, column
        self.paddle = int(self.np_random.integers(BOARD - self.width + 1))  # leftmost column
        self.steps = 0
        return self._image(), self._info()

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.paddle = int(np.clip(self.paddle + int(action) - 1, 0, BOARD - self.width))
        self.ball[0] += 1
        self.steps += 1
        reward, terminated = 0.0, False
        if self.ball[0] == BOARD - 1:
            caught = self.paddle <= self.ball[1] < self.paddle + self.width
            reward, terminated = (1.0 if caught else -1.0), True
        truncated = not terminated and self.steps >= self.limit
        return self._image(), reward, terminated, truncated, self._info()

    def render(self) -> np.ndarray:
        return np.kron(self._image(), np.ones((8, 8, 1), np.uint8))

    def _image(self) -> np.ndarray:
        board = np.full((BOARD, BOARD, 3), 245, np.uint8)
        board[min(self.ball[0], BOARD - 1), self.ball[1]] = BALL
        board[BOARD - 1, self.paddle : self.paddle + self.width] = PADDLE
        return np.kron(board, np.ones((PIXELS, PIXELS, 1), np.uint8))

    def _info(self) -> dict[str, Any]:
        middle = self.paddle + self.width // 2
        move = int(np.sign(self.ball[1] - middle)) + 1  # 0 left, 1 stay, 2 right
        under = self.paddle <= self.ball[1] < self.paddle + self.width
        caught = self.ball[0] == BOARD - 1 and under
        return {"correct_action": move, "is_success": caught}


def _make_env(options: TaskOptions, max_episode_steps: int, record_motion: bool) -> gym.Env:
    width = options["paddle_width"]
    assert isinstance(width, int)
    return CatchEnv(width, max_episode_steps)


@task_factory
def catch_task() -> Task:
    return Task(
        name="catch",
        title="Catch the ball",
        make_env=_make_env,
        actions=(
            TaskAction("left", "ArrowLeft"),
            TaskAction("stay", "s"),
            TaskAction("right", "ArrowRight"),
        ),
        goal="Move the blue paddle under the falling red ball.",
        options={"paddle_width": 3},
        good_reward=0.5,
    )
