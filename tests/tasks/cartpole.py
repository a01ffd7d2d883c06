"""A vector task defined only inside the tests: Gymnasium's CartPole-v1, whose observation
is four numbers (a Box of shape (4,)) and whose two actions push the cart; its learner is
the dense network, from the `modern` preset; people see its rendered frames."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from tasks import Task, TaskAction, TaskOptions, task_factory


def _make_env(
    options: TaskOptions, max_episode_steps: int, record_motion: bool
) -> gym.Env[Any, Any]:
    # Rendered frames are what people see (the cart and pole drawn, 600x400).
    return gym.make("CartPole-v1", max_episode_steps=max_episode_steps, render_mode="rgb_array")


@task_factory
def cartpole_task() -> Task:
    return Task(
        name="cartpole",
        title="Balance the pole",
        make_env=_make_env,
        actions=(TaskAction("push left", "ArrowLeft"), TaskAction("push right", "ArrowRight")),
        goal="Keep the pole upright by pushing the cart left or right.",
        preset="modern",
    )
