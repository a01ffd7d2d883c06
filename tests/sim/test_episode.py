"""The task's rules and rewards, played through the fast mode (SPEC 1)."""

import gymnasium as gym
import numpy as np
import pytest

import sim
from tests.sim.conftest import run_oracle, seed_whose_first_grab_is

GRAB, RIGHT, LEFT, DROP = sim.Action


def test_oracle_sorts_everything_in_18_steps_for_exactly_3(fast_env: sim.SortingEnv) -> None:
    for seed in range(20):
        total, steps, terminated, truncated, info = run_oracle(fast_env, seed)
        assert (total, steps, terminated, truncated) == (3.0, 18, True, False), seed
        assert info["placed_correct"] == 6 and info["remaining"] == 0 and info["is_success"]


@pytest.mark.parametrize(
    "rule", ["shape", {f"{s}/{c}": "left" if c == "red" or s == "disk" else "right"
                       for s in sim.SHAPES for c in sim.COLORS}]
)  # fmt: skip
def test_other_sort_rules_are_played_by_the_env(rule: object) -> None:
    env = sim.SortingEnv(motion="fast", sort_rule=rule)
    try:
        assert run_oracle(env, 11, rule)[:2] == (3.0, 18)
        # ...and the color oracle, right for some objects only, misplaces one.
        _total, _, terminated, _, info = run_oracle(env, 11, "color")
        assert terminated and info["misplaced"] == 1 and not info["is_success"]
    finally:
        env.close()


def test_rewards_of_correct_placements(fast_env: sim.SortingEnv) -> None:
    _, info = fast_env.reset(seed=0)
    rewards = []
    for _ in range(18):
        _, reward, _terminated, _, info = fast_env.step(sim.oracle_action(info, "color"))
        rewards.append(reward)
    assert rewards == [0.0, 0.0, 0.4] * 5 + [0.0, 0.0, 1.0]


def test_a_wrong_placement_costs_1_and_ends_the_episode(fast_env: sim.SortingEnv) -> None:
    seed = seed_whose_first_grab_is(fast_env, "red")
    fast_env.reset(seed=seed)
    fast_env.step(GRAB)
    fast_env.step(RIGHT)  # red belongs left
    _, reward, terminated, truncated, info = fast_env.step(DROP)
    assert (reward, terminated, truncated) == (-1.0, True, False)
    assert info["misplaced"] == 1 and info["held"] == "" and not info["is_success"]


def test_steps_after_the_18th_without_placement_cost_a_hundredth(
    fast_env: sim.SortingEnv,
) -> None:
    fast_env.reset(seed=1)
    rewards = [fast_env.step(RIGHT if i % 2 else LEFT)[1] for i in range(22)]
    assert rewards == [0.0] * 18 + [-0.01] * 4
    # A correct placement after the 18th step earns its 0.4, not 0.39.
    _, _, _, _, info = fast_env.step(GRAB)
    assert fast_env.step(sim.oracle_action(info, "color"))[1] == -0.01
    assert fast_env.step(DROP)[1] == 0.4


def test_an_episode_is_truncated_not_terminated_after_250_steps(
    fast_env: sim.SortingEnv,
) -> None:
    fast_env.reset(seed=2)
    for step in range(1, 251):
        _, reward, terminated, truncated, info = fast_env.step(LEFT if step % 2 else RIGHT)
        assert not terminated and truncated == (step == 250)
        assert reward == (0.0 if step <= 18 else -0.01)
    assert info["episode_step"] == 250 and info["remaining"] == 6


@pytest.mark.parametrize("limit", [20, 300])
def test_the_step_limit_can_be_changed_directly_or_through_gym_make(limit: int) -> None:
    for env in (
        sim.SortingEnv(motion="fast", max_episode_steps=limit),
        gym.make(sim.ENV_ID, motion="fast", max_episode_steps=limit),
    ):
        try:
            env.reset(seed=0)
            results = [env.step(LEFT if i % 2 else RIGHT)[3] for i in range(limit)]
            assert results == [False] * (limit - 1) + [True]
        finally:
            env.close()


def test_grab_while_holding_returns_above_the_center_still_holding(
    fast_env: sim.SortingEnv,
) -> None:
    obs_center_holding, info = fast_env.reset(seed=3)
    obs_center_holding, _, _, _, info = fast_env.step(GRAB)
    held = info["held"]
    _, _, _, _, info = fast_env.step(LEFT)
    assert info["station"] == "left"
    obs, reward, terminated, _, info = fast_env.step(GRAB)
    assert (info["station"], info["held"], reward, terminated) == ("center", held, 0.0, False)
    assert info["remaining"] == 5
    assert np.array_equal(obs, obs_center_holding)


def test_no_op_actions_change_nothing_but_the_step_count(fast_env: sim.SortingEnv) -> None:
    obs0, _info0 = fast_env.reset(seed=4)
    cases = [
        (DROP, "center"),  # not holding
        (GRAB, "center"),  # picks one...
        (GRAB, "center"),  # ...grab again while holding at the center: stays
        (DROP, "center"),  # holding at the center: keeps the position
        (RIGHT, "right"),
        (RIGHT, "right"),  # already there
    ]
    previous = obs0
    for action, station in cases:
        obs, reward, terminated, _, info = fast_env.step(action)
        assert (info["station"], reward, terminated) == (station, 0.0, False)
        changed = not np.array_equal(obs, previous)
        assert changed == ((action, info["episode_step"]) in {(GRAB, 2), (RIGHT, 5)})
        previous = obs
    assert info["held"] != "" and info["placed_correct"] == 0
