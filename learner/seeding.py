"""A run's random streams, from its one seed: the network's initialisation, the
environment's reset seeds, the actions, and memory sampling, each its own stream so that
changing how one is used leaves the others as they were.

Torch-free, so that a study's records can be replayed without the learner: the k-th
episode of a run (pretraining and training in the order they ran, from 0) began with
`reset_seeds(seed, k + 1)[k]`, also when the run was cut short before the episode's
record was written.
"""

from __future__ import annotations

import numpy as np

MAX_RESET_SEED = 2**31 - 1


def run_streams(seed: int) -> list[np.random.SeedSequence]:
    """(init, env, actions, memory): the trainer's four streams."""
    return np.random.SeedSequence(seed).spawn(4)


def draw_reset_seed(rng: np.random.Generator) -> int:
    """The next episode's reset seed from the env stream's generator."""
    return int(rng.integers(MAX_RESET_SEED))


def reset_seeds(seed: int, count: int) -> list[int]:
    """The reset seeds of a run's first `count` episodes."""
    rng = np.random.default_rng(run_streams(seed)[1])
    return [draw_reset_seed(rng) for _ in range(count)]
