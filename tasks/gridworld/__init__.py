"""A grid world (MiniGrid's empty room): the agent, a red triangle, walks to the green goal
square. Four moves, seen from above (up, right, down, left), so a person names a move as
they see it; the learner sees the whole room from above, 8 pixels a square.

The correct action is a shortest path's next move (a breadth-first search over the room,
done once an episode), stated in `info["correct_action"]`: the first in action order of
the moves that bring the agent a step nearer the goal, all of which
`info["correct_actions"]` lists (above and left of the goal, right and down both do;
advice naming either is right). The reward is MiniGrid's: on reaching the goal, 1 - 0.9 x
(steps taken / the step limit); nothing otherwise. Recorded runs are rescored under the
other schemes (`SCHEMES`) from where each episode reached the goal (the step that ended
it: the room ends an episode nowhere else).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np

from tasks import (
    CheckQuestion,
    RecordedEpisode,
    RewardSchemes,
    Task,
    TaskAction,
    TaskOptions,
    task_factory,
)

TILE = 8
"""Pixels a square in what the learner sees."""
PEOPLE_TILE = 32
"""Pixels a square in what people see."""
MOVES = ((0, -1), (1, 0), (0, 1), (-1, 0))
"""Action i's step (dx, dy) on the grid: up, right, down, left."""
DIRECTION = (3, 0, 1, 2)
"""MiniGrid's facing for action i (0 right, 1 down, 2 left, 3 up)."""
OPTIONS: dict[str, Any] = {"size": 8, "max_steps": 64}
"""The room's side in squares (walls included; the image is 8 x size pixels a side) and
MiniGrid's own step limit, which its reward counts against."""
SCHEMES = ("minigrid", "sparse", "step-cost")
"""What reaching the goal at the n-th step of an episode earns, and what other steps cost:
- `minigrid` (how runs are scored): 1 - 0.9 x n / max_steps at the goal, 0 otherwise;
- `sparse`: 1 at the goal, 0 otherwise (only whether it got there counts);
- `step-cost`: 1 at the goal, -0.01 every other step (every step counts the same)."""
STEP_COST = -0.01
ABOUT = (
    "The step that reached the goal earns what the scheme gives it there, every other step "
    "what the scheme costs (`tasks.gridworld.SCHEMES`)."
)
"""How its runs are rescored, for the report."""


class GridWorldEnv(gym.Env[np.ndarray, int]):
    """MiniGrid's EmptyEnv with a random start, moved by absolute steps."""

    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012 (Gymnasium's own attribute)

    def __init__(self, size: int = 8, max_steps: int = 64, max_episode_steps: int = 250) -> None:
        from minigrid.envs import EmptyEnv  # imported when an environment is made

        if not (isinstance(size, int) and 4 <= size <= 16):
            raise ValueError(f"gridworld size must be an int from 4 to 16, got {size!r}")
        if not (isinstance(max_steps, int) and 1 <= max_steps <= 10_000):
            raise ValueError(
                f"gridworld max_steps must be an int from 1 to 10000, got {max_steps!r}"
            )
        self._grid = EmptyEnv(size=size, agent_start_pos=None, max_steps=max_steps)
        self.limit = min(max_steps, max_episode_steps)
        self.observation_space = gym.spaces.Box(0, 255, (size * TILE, size * TILE, 3), np.uint8)
        self.action_space = gym.spaces.Discrete(len(MOVES))  # type: ignore[assignment]
        self.render_mode = "rgb_array"
        self._distance: dict[tuple[int, int], int] = {}
        self._steps = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._grid.reset(seed=seed)
        self._steps = 0
        self._distance = self._distances()
        return self._image(TILE), self._info()

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"gridworld actions are 0 to {len(MOVES) - 1}, got {action!r}")
        grid = self._grid
        grid.agent_dir = DIRECTION[int(action)]
        _, reward, terminated, truncated, _ = grid.step(grid.actions.forward)
        self._steps += 1
        truncated = bool(truncated or (self._steps >= self.limit and not terminated))
        return self._image(TILE), float(reward), bool(terminated), truncated, self._info()

    def render(self) -> np.ndarray:
        """What people see: the room at 32 pixels a square."""
        return self._image(PEOPLE_TILE)

    def close(self) -> None:
        self._grid.close()

    def _image(self, tile: int) -> np.ndarray:
        return np.ascontiguousarray(self._grid.get_frame(highlight=False, tile_size=tile))

    def _position(self) -> tuple[int, int]:
        x, y = self._grid.agent_pos
        return int(x), int(y)

    def _info(self) -> dict[str, Any]:
        position = self._position()
        nearer = self._moves_nearer(position)
        return {
            "position": position,
            "distance": self._distance.get(position),
            "correct_action": nearer[0] if nearer else None,
            "correct_actions": nearer,
            "is_success": self._distance.get(position) == 0,
        }

    def _open(self, x: int, y: int) -> bool:
        cell = self._grid.grid.get(x, y)
        return cell is None or cell.can_overlap()

    def _distances(self) -> dict[tuple[int, int], int]:
        """Each open square's steps to the goal (breadth-first from the goal)."""
        grid = self._grid.grid
        goals = [
            (x, y)
            for x in range(grid.width)
            for y in range(grid.height)
            if (cell := grid.get(x, y)) is not None and cell.type == "goal"
        ]
        distance = dict.fromkeys(goals, 0)
        queue = deque(goals)
        while queue:
            x, y = queue.popleft()
            for dx, dy in MOVES:
                near = (x + dx, y + dy)
                if near not in distance and self._open(*near):
                    distance[near] = distance[(x, y)] + 1
                    queue.append(near)
        return distance

    def _moves_nearer(self, position: tuple[int, int]) -> list[int]:
        """The moves (in action order) that bring the agent a step nearer the goal; none at
        the goal."""
        here = self._distance.get(position)
        if not here:
            return []
        return [
            action
            for action, (dx, dy) in enumerate(MOVES)
            if self._distance.get((position[0] + dx, position[1] + dy), here) < here
        ]


def goal_reward(scheme: str, n: int, max_steps: int) -> float:
    """What reaching the goal at the `n`-th step (from 1) earns under `scheme`."""
    return 1 - 0.9 * (n / max_steps) if scheme == "minigrid" else 1.0


def _rescore(
    episode: RecordedEpisode, scheme: str, to_scheme: str, options: TaskOptions
) -> list[float]:
    """The goal's step earns what `to_scheme` gives it there, every other step its cost."""
    if scheme == to_scheme:
        return list(episode.rewards)
    max_steps = options["max_steps"]
    assert isinstance(max_steps, int), "the task's option"
    other = STEP_COST if to_scheme == "step-cost" else 0.0
    return [
        goal_reward(to_scheme, n, max_steps) if ended else other
        for n, ended in enumerate(episode.terminated, start=1)
    ]


def _make_env(
    options: TaskOptions, max_episode_steps: int, record_motion: bool
) -> gym.Env[Any, Any]:
    size, max_steps = options["size"], options["max_steps"]
    assert isinstance(size, int) and isinstance(max_steps, int), "checked by the task"
    return GridWorldEnv(size, max_steps, max_episode_steps)


@task_factory
def gridworld_task() -> Task:
    return Task(
        name="gridworld",
        title="Grid world",
        make_env=_make_env,
        actions=(
            TaskAction("up", "ArrowUp"),
            TaskAction("right", "ArrowRight"),
            TaskAction("down", "ArrowDown"),
            TaskAction("left", "ArrowLeft"),
        ),
        goal="Bring the red triangle to the green square in as few moves as you can.",
        options=OPTIONS,
        good_reward=0.5,
        reward_schemes=RewardSchemes(SCHEMES, _rescore, about=ABOUT),
        check_questions=(
            CheckQuestion(
                "gridworld_goal",
                "Where should the red triangle go?",
                ("To the green square", "To a wall", "Anywhere"),
                "To the green square",
            ),
            CheckQuestion(
                "gridworld_moves",
                "What does the 'up' button do?",
                (
                    "Moves the triangle one square up, as you see the room",
                    "Turns the triangle",
                    "Ends the episode",
                ),
                "Moves the triangle one square up, as you see the room",
            ),
        ),
    )
