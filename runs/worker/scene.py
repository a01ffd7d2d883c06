"""A Gymnasium wrapper that tells the web process what the scene does, for the viewer,
and keeps the current episode's collected reward for progress reports."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, SupportsFloat, cast

import gymnasium as gym

from runs.worker.link import WorkerLink
from runs.worker.messages import SceneReset, SceneStep

if TYPE_CHECKING:
    from runs.worker.advisors import HumanAdvisor
    from runs.worker.rating import HumanEvaluator
    from sim.env import SortingEnv


class SceneBroadcast(gym.Wrapper):
    def __init__(self, env: gym.Env, link: WorkerLink | None, live_view: bool = True) -> None:
        super().__init__(env)
        self._link = link if live_view else None
        """Where the scene goes: none for a task without a live 3-D view (its page shows
        frames, which come with each advice request)."""
        self.collected_reward = 0.0
        self.steps = 0
        self.episode = -1
        self.after_step: list[Callable[[int, float, bool], None]] = []
        """Called with (action, reward, episode_over) after every step."""
        self.participant: HumanAdvisor | HumanEvaluator | None = None
        """A human session's advisor: whether the step being taken carries out its advice,
        or is the one they will rate (asked before `after_step` runs), tells the view which
        steps to animate."""

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self.collected_reward = 0.0
        if self._link is not None and self._link.watching:
            self.announce()
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        advised = self.participant is not None and self.participant.carrying_out
        self.collected_reward += float(reward)
        self.steps += 1
        for hook in self.after_step:
            hook(int(action), float(reward), bool(terminated or truncated))
        if self._link is not None and self._link.watching:
            scene = scene_of(self.env)
            self._link.send(
                SceneStep(
                    action=int(action),
                    reward=float(reward),
                    frames=list(getattr(scene, "last_motion", None) or []),
                    poses=dict(scene.body_poses()),
                    global_step=self.steps,
                    advised=advised,
                )
            )
        return obs, reward, terminated, truncated, info

    def announce(self) -> None:
        """Send the whole scene (bodies and poses): on reset, and when a viewer arrives
        (none for a task without a live view)."""
        if self._link is None:
            return
        scene = scene_of(self.env)
        self._link.send(
            SceneReset(
                bodies=list(scene.scene_bodies()),
                poses=dict(scene.body_poses()),
                episode=self.episode,
            )
        )


def scene_of(env: gym.Env[Any, Any]) -> SortingEnv:
    """The sorting scene under a run's wrappers (imported by name only: the web process
    imports this module and loads no simulation)."""
    return cast("SortingEnv", env.unwrapped)
