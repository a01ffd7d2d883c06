from collections.abc import Iterator

import pytest

import sim
from learner import DQNConfig


@pytest.fixture
def make_env() -> Iterator:
    """Real sorting environments in fast mode, closed after the test."""
    envs = []

    def make(**options) -> sim.SortingEnv:
        env = sim.SortingEnv(motion="fast", **options)
        envs.append(env)
        return env

    yield make
    for env in envs:
        env.close()


def small_config(**changes) -> DQNConfig:
    """The paper's algorithm at a scale a test can afford."""
    values = {
        "episodes": 3,
        "pretraining_steps": 60,
        "advice_budget": 20,
        "batch_size": 16,
        "memory_size": 500,
        "max_episode_steps": 30,
        "epsilon_decay": 0.99,
    }
    return DQNConfig.from_dict({**values, **changes})


class Recorder:
    """A callback keeping every record."""

    def __init__(self) -> None:
        self.steps: list = []
        self.episodes: list = []

    def on_step(self, record) -> None:
        self.steps.append(record)

    def on_episode(self, record) -> None:
        self.episodes.append(record)
