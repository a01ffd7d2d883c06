"""The Gymnasium contract and what happens on bad input."""

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env

import sim
from tests.sim.conftest import replay


@pytest.mark.parametrize("motion", ["fast", "physics"])
def test_gymnasium_env_checker_passes(motion: str) -> None:
    env = gym.make(sim.ENV_ID, motion=motion)
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


def test_import_registers_the_id_and_names_the_actions() -> None:
    env = gym.make("ideeprl/Sorting-v0", motion="fast")
    try:
        assert isinstance(env.unwrapped, sim.SortingEnv)
        assert env.spec is not None and env.spec.max_episode_steps == 250
        obs, _info = env.reset(seed=3)
        assert obs.shape == (64, 64, 3) and obs.dtype == np.uint8
        assert env.action_space.n == 4
    finally:
        env.close()
    assert [a.value for a in sim.Action] == [0, 1, 2, 3]
    assert [a.name for a in sim.Action] == ["GRAB", "MOVE_RIGHT", "MOVE_LEFT", "DROP"]
    assert sim.ACTION_NAMES == ("grab", "move right", "move left", "drop")


def test_info_holds_the_ground_truth(fast_env: sim.SortingEnv) -> None:
    _, info = fast_env.reset(seed=0)
    assert info["station"] == "center" and info["held"] == ""
    assert (info["held_shape"], info["held_color"]) == ("", "")
    assert info["remaining"] == 6 and info["on_center"] == (True,) * 6
    assert (info["placed_correct"], info["misplaced"], info["lost"]) == (0, 0, 0)
    assert info["episode_step"] == 0
    _, _, _, _, info = fast_env.step(sim.Action.GRAB)
    assert info["held"] == f"{info['held_shape']}/{info['held_color']}"
    assert not info["on_center"][sim.OBJECTS.index(info["held"])]
    assert info["remaining"] == 5 and info["episode_step"] == 1


def test_the_scenario_does_not_need_pybullet_until_the_env_is_used() -> None:
    """A viewer or analysis script can use the actions, rules, oracle and scene types."""
    code = (
        "import sys; sys.modules['pybullet'] = None\n"
        "import sim\n"
        "assert sim.oracle_action({'held': None, 'station': 'left'}, 'color') == 0\n"
        "assert sim.BodySpec and sim.Pose and sim.MotionFrame\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).parents[2])


@pytest.mark.parametrize("bad", [4, -1, 1.0, "grab", None, True, np.array([1])])
def test_an_action_outside_0_to_3_raises_and_changes_nothing(
    fast_env: sim.SortingEnv, bad: object
) -> None:
    actions = [sim.Action.GRAB, sim.Action.MOVE_LEFT, sim.Action.MOVE_RIGHT, sim.Action.GRAB]
    reference = replay(fast_env, 5, actions)
    obs, info = fast_env.reset(seed=5)
    poses = fast_env.body_poses()
    with pytest.raises(ValueError, match=r"0 \(grab\), 1 \(move right\)"):
        fast_env.step(bad)
    assert fast_env.body_poses() == poses
    trace = [(obs.tobytes(), 0.0, False, False, info)]
    for action in actions:
        obs, reward, terminated, truncated, info = fast_env.step(action)
        trace.append((obs.tobytes(), reward, terminated, truncated, info))
    assert trace == reference


def test_numpy_integers_and_action_members_are_accepted(fast_env: sim.SortingEnv) -> None:
    fast_env.reset(seed=1)
    for action in (np.int64(0), np.array(1), sim.Action.MOVE_LEFT, 3):
        fast_env.step(action)


@pytest.mark.parametrize("motion", ["fast", "physics"])
def test_stepping_after_the_end_without_reset_raises_and_changes_nothing(motion: str) -> None:
    env = sim.SortingEnv(motion=motion)
    try:
        with pytest.raises(ResetNeeded, match=r"reset\(\)"):
            env.step(sim.Action.GRAB)  # never reset
        env.reset(seed=2)
        _, _, _, _, info = env.step(sim.Action.GRAB)
        wrong = sim.Action.MOVE_LEFT if info["held_color"] == "blue" else sim.Action.MOVE_RIGHT
        env.step(wrong)
        _, reward, terminated, _, info = env.step(sim.Action.DROP)
        assert terminated and reward == -1.0
        poses = env.body_poses()
        with pytest.raises(ResetNeeded, match=r"call env\.reset\(\)"):
            env.step(sim.Action.GRAB)
        assert env.body_poses() == poses
        _obs, info = env.reset(seed=2)
        assert info["episode_step"] == 0 and info["misplaced"] == 0
    finally:
        env.close()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"motion": "slow"}, r"motion must be .physics. \(the arm moves"),
        ({"max_episode_steps": 0}, "max_episode_steps must be a positive int"),
        ({"sort_rule": "colour"}, 'sort rule is "color"'),
        ({"render_mode": "human"}, "render_mode must be None or 'rgb_array'"),
    ],
)
def test_bad_configuration_is_rejected_with_what_to_do(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        sim.SortingEnv(**kwargs)


def test_rgb_array_render_is_the_agents_image() -> None:
    env = sim.SortingEnv(motion="fast", render_mode="rgb_array")
    try:
        obs, _ = env.reset(seed=4)
        assert np.array_equal(env.render(), obs)
    finally:
        env.close()
