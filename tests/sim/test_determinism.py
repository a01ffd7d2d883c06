"""Same seed and same actions give the same episode, byte for byte, in both modes."""

import numpy as np
import pytest

import sim
from tests.sim.conftest import replay


def sorting_then_wandering(seed: int, wander: int) -> list[int]:
    """Nine oracle actions from `seed` (three placements), then grabs and moves at random."""
    env = sim.SortingEnv(motion="fast")
    _, info = env.reset(seed=seed)
    actions = []
    for _ in range(9):
        actions.append(sim.oracle_action(info, "color"))
        info = env.step(actions[-1])[4]
    env.close()
    rng = np.random.default_rng(seed)
    return actions + rng.integers(0, 3, wander).tolist()


@pytest.mark.parametrize("motion", ["fast", "physics"])
def test_fresh_envs_and_reused_envs_replay_identically(motion: str) -> None:
    actions = sorting_then_wandering(7, wander=15)
    first = sim.SortingEnv(motion=motion)
    second = sim.SortingEnv(motion=motion)
    try:
        reference = replay(first, 7, actions)
        replay(second, 8, actions[::-1])  # leave the second env in another state
        again_in_second = replay(second, 7, actions)
        again_in_first = replay(first, 7, actions)
    finally:
        first.close()
        second.close()
    assert len(reference) == 1 + len(actions)
    assert again_in_second == reference
    assert again_in_first == reference


@pytest.mark.parametrize("motion", ["fast", "physics"])
def test_another_seed_gives_another_episode(motion: str) -> None:
    env = sim.SortingEnv(motion=motion)
    try:
        actions = sorting_then_wandering(1, wander=3)
        assert replay(env, 1, actions) != replay(env, 2, actions)
    finally:
        env.close()
