"""The scenario under tools nobody here wrote: Gymnasium's vector envs, copies and pickles,
Stable-Baselines3's env checker (docs/architecture.md, "sim: the scenario")."""

import copy
import pickle
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import sim
from tests.sim.conftest import replay

ROOT = Path(__file__).parents[2]


def fixed_types(info: dict) -> dict[str, tuple[type, tuple[int, ...]]]:
    return {k: (type(v), np.shape(v)) for k, v in info.items()}


def test_info_has_one_type_and_shape_for_every_key_at_every_step(fast_env) -> None:
    _, info = fast_env.reset(seed=4)
    expected = fixed_types(info)
    rng = np.random.default_rng(0)
    held_seen = set()
    for _ in range(300):
        _, _, terminated, truncated, info = fast_env.step(int(rng.integers(4)))
        assert fixed_types(info) == expected
        held_seen.add(info["held"])
        if terminated or truncated:
            _, info = fast_env.reset()
            assert fixed_types(info) == expected
    assert "" in held_seen and len(held_seen) > 1, "holding and not holding both happened"


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec_runs_two_envs_for_100_random_steps(mode: str) -> None:
    envs = gym.make_vec(sim.ENV_ID, num_envs=2, vectorization_mode=mode, motion="fast")
    try:
        obs, infos = envs.reset(seed=[1, 2])
        assert obs.shape == (2, 64, 64, 3) and obs.dtype == np.uint8
        envs.action_space.seed(3)
        ends = 0
        for _ in range(100):
            obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
            assert obs.shape == (2, 64, 64, 3) and rewards.shape == (2,)
            on_center = np.stack(infos["on_center"])
            assert on_center.shape == (2, 6) and on_center.dtype == np.bool_
            assert infos["remaining"].dtype.kind == "i" and infos["is_success"].dtype == np.bool_
            assert infos["remaining"].tolist() == on_center.sum(axis=1).tolist()
            assert set(infos["station"]) <= {"center", "left", "right"}
            ends += int(np.sum(terminated | truncated))
        assert ends > 0, "random play misplaces objects: episodes ended and auto-reset"
    finally:
        envs.close()


def test_cleanrl_style_sync_vector_env_steps() -> None:
    envs = gym.vector.SyncVectorEnv(
        [lambda: gym.make("sim:ideeprl/Sorting-v0", motion="fast") for _ in range(2)]
    )
    try:
        envs.reset(seed=0)
        for _ in range(20):
            _, _, _, _, infos = envs.step(np.array([0, 3]))
        assert infos["held"].shape == (2,)
    finally:
        envs.close()


def test_gym_make_with_the_module_prefix_needs_no_import_first() -> None:
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('sim:ideeprl/Sorting-v0', motion='fast')\n"
        "obs, info = env.reset(seed=0)\n"
        "assert obs.shape == (64, 64, 3) and info['held'] == ''\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


@pytest.mark.parametrize("motion", ["fast", "physics"])
def test_a_deepcopy_has_its_own_connection_and_the_same_state(motion: str) -> None:
    env = sim.SortingEnv(motion=motion)
    actions = [0, 1, 3, 0, 2]
    try:
        env.reset(seed=5)
        for action in actions[:3]:
            env.step(action)
        clone = copy.deepcopy(env)
        assert clone._world.p.id != env._world.p.id
        rest_original = [env.step(a) for a in actions[3:]]
        rest_clone = [clone.step(a) for a in actions[3:]]
        for a, b in zip(rest_original, rest_clone, strict=True):
            assert np.array_equal(a[0], b[0]) and a[1:4] == b[1:4]
            assert a[4] == b[4]
        clone.close()
        del clone
        # The original still talks to its own physics server.
        assert len(replay(env, 5, actions)) == 1 + len(actions)
    finally:
        env.close()


def test_a_pickled_env_comes_back_in_the_same_state_and_a_wrapped_one_too() -> None:
    env = gym.make(sim.ENV_ID, motion="fast")
    try:
        env.reset(seed=9)
        env.step(0)
        clone = pickle.loads(pickle.dumps(env))
        deep = copy.deepcopy(env)
        expected = env.step(1)
        for other in (clone, deep):
            got = other.step(1)
            assert np.array_equal(got[0], expected[0]) and got[1:4] == expected[1:4]
            other.close()
        env.step(3)
    finally:
        env.close()


def test_a_bare_pybullet_client_refuses_to_be_copied(fast_env) -> None:
    with pytest.raises(TypeError, match="copy the SortingEnv"):
        copy.deepcopy(fast_env._world.p)
    with pytest.raises(TypeError, match="pickle the SortingEnv"):
        pickle.dumps(fast_env._world.p)


def test_stable_baselines3_check_env_passes() -> None:
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(sim.ENV_ID, motion="fast")
    try:
        env_checker.check_env(env, warn=True)
    finally:
        env.close()
