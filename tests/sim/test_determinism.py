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


@pytest.mark.parametrize("seed", [3, 4])
def test_watching_or_recording_the_motion_does_not_change_what_happens(seed: int) -> None:
    """A person's session records its motion for the 3-D view and a live viewer reads the
    poses after every step; a batch run does neither. All three must take the same course:
    a grasp read the cup's pose from PyBullet's cached link state, which recording
    refreshes, so a recorded run once held a grabbed object differently (and diverged)."""
    rng = np.random.default_rng(seed)
    actions = rng.integers(0, 4, 60).tolist()
    plain = sim.SortingEnv(motion="physics")
    recorded = sim.SortingEnv(motion="physics", record_motion=True)
    watched = sim.SortingEnv(motion="physics")
    try:
        runs = []
        for env, watch in ((plain, False), (recorded, False), (watched, True)):
            obs, _ = env.reset(seed=seed)
            course = [obs.tobytes()]
            for action in actions:
                obs, reward, terminated, truncated, _ = env.step(action)
                if watch:
                    env.unwrapped.body_poses()
                course.append((obs.tobytes(), reward, terminated))
                if terminated or truncated:
                    break
            runs.append(course)
    finally:
        for env in (plain, recorded, watched):
            env.close()
    first_difference = [
        next((i for i, (a, b) in enumerate(zip(runs[0], other, strict=False)) if a != b), None)
        for other in runs[1:]
    ]
    assert first_difference == [None, None]
    assert [len(r) for r in runs[1:]] == [len(runs[0])] * 2
