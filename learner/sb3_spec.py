"""The SB3 baseline's hyperparameters, without Stable-Baselines3 or torch.

What a run, a stored session and the report's audit need of the `sb3-dqn` baseline (its
`sb3_*` fields, their values for a config, the learner in one line) without the trainer
(`learner.sb3_dqn`), which drives SB3: `RunSpec.sb3` maps a config here, and the analysis,
which must import nothing of the runtime, describes the learner from here.
"""

from __future__ import annotations

import math
from typing import Any

from learner.config import DQNConfig

METHOD = "sb3-dqn"
PREFIX = "sb3_"
VECTOR_POLICY = "MlpPolicy"
"""SB3's policy on a task whose observations are float vectors; `sb3_policy` is the one on
images (the trainer sees which from the environment, as the paper's learner chooses its
network)."""


def exploration_steps(config: DQNConfig) -> int:
    """Training steps the config's `epsilon_decay` takes from `epsilon_start` to
    `epsilon_min` (0: epsilon does not move)."""
    start, floor, decay = config.epsilon_start, config.epsilon_min, config.epsilon_decay
    if decay >= 1.0 or start <= floor:
        return 0
    if floor <= 0.0:
        raise ValueError("sb3-dqn needs epsilon_min above 0 to map the decay onto SB3's schedule")
    return math.ceil(math.log(floor / start) / math.log(decay))


def sb3_hyperparameters(config: DQNConfig) -> dict[str, Any]:
    """SB3 DQN's arguments for the paper's config: its numbers where SB3 has the same knob,
    SB3's own choices (network, loss, optimizer) where the paper's learner is its own."""
    return {
        "sb3_policy": "CnnPolicy",
        "sb3_learning_rate": config.learning_rate,
        "sb3_gamma": config.gamma,
        "sb3_batch_size": config.batch_size,
        "sb3_buffer_size": config.memory_size,
        "sb3_learning_starts": config.pretraining_steps,
        "sb3_train_freq": 1,
        "sb3_gradient_steps": 1,
        "sb3_target_update_interval": (
            config.target_update_interval if config.target_network else 1
        ),
        "sb3_tau": 1.0,
        "sb3_exploration_initial_eps": config.epsilon_start,
        "sb3_exploration_final_eps": config.epsilon_min,
        "sb3_exploration_steps": exploration_steps(config),
        "sb3_loss": "huber",
        "sb3_optimizer": "adam",
        "sb3_max_grad_norm": (
            float(config.grad_clip_norm) if config.grad_clip_norm is not None else 10.0
        ),
    }


def describe(hyper: dict[str, Any], config: dict[str, Any]) -> str:
    """The learner in one line, for the report's audit: SB3's hyperparameters and the
    episode limit its stages share with the paper's learner."""
    shown = {**hyper, "sb3_policy": f"{hyper['sb3_policy']} ({VECTOR_POLICY} on vectors)"}
    items = ", ".join(f"{k.removeprefix(PREFIX)}={v}" for k, v in sorted(shown.items()))
    limit = config.get("max_episode_steps")
    return f"{METHOD} (Stable-Baselines3 DQN: {items}; max_episode_steps={limit})"
