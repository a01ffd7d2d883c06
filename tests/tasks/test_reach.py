"""The reach task: PyBullet's iiwa brings its hand to a red ball, one move along an axis a
step; its oracle reaches the ball, its moves go where the page's words say, and a batch of
autonomous and oracle-advised agents runs it through `ideeprl batch`."""

from __future__ import annotations

import csv
import subprocess
from pathlib import Path

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from tasks import get_task
from tasks.reach.env import LATTICE, STEP, ReachEnv, lattice_point
from tests import in_process


@pytest.fixture(scope="module")
def env() -> ReachEnv:
    made = get_task("reach").env({}, 250, False)
    yield made.unwrapped
    made.close()


def test_the_reach_task_is_a_gymnasium_env_of_images_for_the_learner(env: ReachEnv) -> None:
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (64, 64, 3) and obs.dtype == np.uint8
    red = (obs[..., 0] > 150) & (obs[..., 1] < 60) & (obs[..., 2] < 60)
    assert red[:32].sum() >= 4 and red[32:].sum() >= 4  # the ball, from above and the side
    task = get_task("reach")
    assert task.n_actions == 6 and task.live_view and task.camera is not None
    assert len({a.key for a in task.actions}) == 6


def test_the_oracles_moves_reach_the_ball_by_the_shortest_way(env: ReachEnv) -> None:
    for seed in range(8):
        _, info = env.reset(seed=seed)
        shortest = sum(abs(g - h) for g, h in zip(info["goal"], info["hand"], strict=True))
        start = info["distance"]
        steps, total = 0, 0.0
        while True:
            before = info["distance"]
            _, reward, terminated, truncated, info = env.step(info["correct_action"])
            steps, total = steps + 1, total + reward
            assert info["distance"] < before  # each of its moves brings the hand nearer
            if terminated or truncated:
                break
        assert terminated and not truncated and info["is_success"] and steps == shortest
        assert info["correct_action"] is None
        assert total == pytest.approx(1.0 + 0.1 * start / STEP)  # the ball, and the way
        hand = np.array(env.p.getLinkState(env.arm, 6)[4])
        assert np.linalg.norm(hand - lattice_point(tuple(info["goal"]))) < 0.005


def test_moves_go_where_the_page_says_and_the_box_stops_them(env: ReachEnv) -> None:
    words = get_task("reach").action_words
    assert words == ("move forward", "move back", "move left", "move right", "move up",
                     "move down")  # fmt: skip
    env.reset(seed=3)
    axis = {"forward": (0, 1), "back": (0, -1), "left": (1, 1), "right": (1, -1),
            "up": (2, 1), "down": (2, -1)}  # fmt: skip
    for action, word in enumerate(words):
        env.reset(seed=3)
        env.hand = (2, 3, 2)  # the box's middle
        env._place_arm()
        before = env.hand_position()
        env.step(action)
        moved = env.hand_position() - before
        i, sign = axis[word.split()[1]]
        assert moved[i] * sign == pytest.approx(STEP, abs=0.003)
        assert np.abs(np.delete(moved, i)).max() < 0.003
    env.reset(seed=3)
    env.hand = (LATTICE[0][1] - 1, 0, 0)
    env._place_arm()
    _, reward, *_ = env.step(0)  # forward, at the box's far side
    assert env.hand == (LATTICE[0][1] - 1, 0, 0) and reward == 0.0


def test_the_same_seed_and_moves_give_the_same_images() -> None:
    runs = []
    for _ in range(2):
        env = get_task("reach").env({"max_steps": 5}, 250, False)
        obs, _ = env.reset(seed=11)
        seen = [obs]
        for action in (0, 2, 4, 5, 1):
            obs, _, terminated, truncated, _ = env.step(action)
            seen.append(obs)
            if terminated or truncated:
                break
        runs.append(seen)
        env.close()
    assert len(runs[0]) == len(runs[1]) and truncated
    assert all(np.array_equal(a, b) for a, b in zip(*runs, strict=True))


@pytest.mark.slow
def test_the_reach_task_runs_a_batch_of_autonomous_and_advised_agents(tmp_path: Path) -> None:
    def ideeprl(*args: str) -> subprocess.CompletedProcess[str]:
        return in_process.ideeprl(*args, "--data-dir", str(tmp_path / "data"))

    batch = ideeprl("batch", "--study", "reach", "--task", "reach", "--methods", "autonomous",
                    "oracle", "--agents", "1", "--no-progress", "--episodes", "2",
                    "--pretraining-steps", "40", "--advice-budget", "10",
                    "--max-episode-steps", "20", "--set", "batch_size=8", "--set",
                    "memory_size=200", "--torch-threads", "1")  # fmt: skip
    assert batch.returncode == 0, batch.stderr
    exported = ideeprl("export", "--study", "reach", "--out", str(tmp_path / "out"))
    assert exported.returncode == 0, exported.stderr
    with open(tmp_path / "out" / "sessions.csv") as f:
        sessions = list(csv.DictReader(f))
    assert sorted(s["method"] for s in sessions) == ["autonomous", "oracle"]
    assert {s["task"] for s in sessions} == {"reach"}
    with open(tmp_path / "out" / "steps.csv") as f:
        steps = list(csv.DictReader(f))
    q = [f"q_move_{w}" for w in ("forward", "back", "left", "right", "up", "down")]
    assert steps and [c for c in steps[0] if c.startswith("q_")] == q
    assert all(s[c] != "" for s in steps for c in q)
    advised = [s for s in steps if s["advised_action"] != ""]
    assert len(advised) == 10
