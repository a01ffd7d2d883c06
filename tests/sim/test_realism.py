"""Realism options: failed grasps and objects knocked off, at their configured rates,
deterministic under a seed."""

import numpy as np
import pytest

import sim

GRAB = sim.Action.GRAB


def grab_outcomes(rate_fail: float, rate_knock: float, episodes: int) -> tuple[int, int, int]:
    """(grabs tried from an empty cup, grabs that came back empty, objects knocked off) over
    oracle-driven episodes in fast mode."""
    env = sim.SortingEnv(motion="fast", grasp_failure_rate=rate_fail, knock_off_rate=rate_knock)
    tried = failed = knocked = 0
    for seed in range(episodes):
        _, info = env.reset(seed=seed)
        done = False
        while not done:
            action = sim.oracle_action(info, env.sort_rule)
            before = info
            _, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            if action == GRAB and before["held"] == "" and before["remaining"]:
                tried += 1
                failed += info["held"] == ""
                knocked += info["lost"] - before["lost"]
    env.close()
    return tried, failed, knocked


@pytest.mark.slow
def test_rates_match_their_setting() -> None:
    tried, failed, knocked = grab_outcomes(0.2, 0.1, 150)
    assert tried > 800
    # binomial: 3 standard deviations either side
    for count, rate, trials in ((failed, 0.2, tried), (knocked, 0.1, tried - failed)):
        sd = np.sqrt(trials * rate * (1 - rate))
        assert abs(count - rate * trials) < 3 * sd + 5, (count, rate, trials)


def test_knocked_off_objects_make_best_episodes_fluctuate() -> None:
    env = sim.SortingEnv(motion="fast", knock_off_rate=0.1)
    returns, lost = [], 0
    for seed in range(40):
        _, info = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            _, reward, terminated, truncated, info = env.step(
                sim.oracle_action(info, env.sort_rule)
            )
            total += reward
            done = terminated or truncated
        assert info["is_success"] and info["misplaced"] == 0
        returns.append(total)
        lost += info["lost"]
    assert lost > 0
    assert min(returns) < 3.0 - 0.3 and max(returns) == pytest.approx(3.0)
    env.close()


def test_off_means_no_draw_and_no_change() -> None:
    assert grab_outcomes(0.0, 0.0, 20)[1:] == (0, 0)


@pytest.mark.parametrize("motion", ["fast", "physics"])
def test_deterministic_with_realism_on(motion) -> None:
    def run() -> tuple[list[bytes], list[float], list[dict]]:
        env = sim.SortingEnv(motion=motion, grasp_failure_rate=0.3, knock_off_rate=0.3)
        frames, rewards, infos = [], [], []
        obs, info = env.reset(seed=11)
        actions = np.random.default_rng(5).integers(4, size=40 if motion == "fast" else 20)
        for action in actions:
            obs, reward, terminated, truncated, info = env.step(int(action))
            frames.append(obs.tobytes())
            rewards.append(reward)
            infos.append(info)
            if terminated or truncated:
                obs, info = env.reset(seed=int(action) + 100)
        env.close()
        return frames, rewards, infos

    assert run() == run()


@pytest.mark.parametrize("name", ["grasp_failure_rate", "knock_off_rate"])
@pytest.mark.parametrize("value", [-0.1, 1.5, float("nan"), True, "0.1"])
def test_bad_rates_are_refused(name, value) -> None:
    with pytest.raises(ValueError, match=name):
        sim.SortingEnv(motion="fast", **{name: value})


def test_a_copy_goes_on_like_the_original_with_realism_on() -> None:
    import copy

    env = sim.SortingEnv(motion="fast", grasp_failure_rate=0.3, knock_off_rate=0.3,
                         reward_scheme="authors-autonomous")  # fmt: skip
    _, info = env.reset(seed=4)
    for _ in range(7):
        _, _, _, _, info = env.step(sim.oracle_action(info, env.sort_rule))
    twin = copy.deepcopy(env)
    assert (twin.reward_scheme, twin.knock_off_rate) == ("authors-autonomous", 0.3)
    twin_info = info
    for _ in range(12):
        a = env.step(sim.oracle_action(info, env.sort_rule))
        b = twin.step(sim.oracle_action(twin_info, twin.sort_rule))
        info, twin_info = a[4], b[4]
        assert a[0].tobytes() == b[0].tobytes() and a[1:] == b[1:]
        if a[2] or a[3]:
            break
    twin.close()
    env.close()
