"""The learner learns the task: with an oracle's early advice, at a scale CI can afford."""

import numpy as np
import pytest

from learner import DQNConfig, Trainer, make_advisor


def collected_rewards(make_env, learning_rate: float) -> list[float]:
    config = DQNConfig(
        episodes=25,
        max_episode_steps=40,
        pretraining_steps=300,
        advice_budget=100,  # early advising: steps 201-300
        batch_size=32,
        memory_size=3000,
        epsilon_decay=0.99,  # exploration ends after ~460 updates instead of ~9,200
        learning_rate=learning_rate,
    )
    trainer = Trainer(
        make_env(max_episode_steps=40), config, make_advisor("oracle", seed=0), seed=0
    )
    return [episode.collected_reward for episode in trainer.run()]


@pytest.mark.slow
def test_collected_reward_rises_and_does_not_without_learning(make_env) -> None:
    learned = collected_rewards(make_env, learning_rate=1e-3)
    frozen = collected_rewards(make_env, learning_rate=0.0)

    def gain(rewards: list[float]) -> float:
        return float(np.mean(rewards[-5:]) - np.mean(rewards[:5]))

    assert gain(learned) >= 1.0, learned
    assert np.mean(learned[-5:]) >= 1.0, learned
    assert gain(frozen) < 1.0, frozen  # the same check fails when the network cannot learn
