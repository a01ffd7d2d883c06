"""Rescoring goes through the task: the grid world's and the reach task's recorded runs are
rescored under their own schemes, checked against sums done by hand; a task without
schemes, or a scheme the record cannot give, is refused with the reason, never a number."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from analysis.rescoring import STEP_COLUMNS, plan, rescored_totals
from tasks import RecordedEpisode, RescoreError, get_task

GRID = {"size": 6, "max_steps": 40}
"""A room of 4 x 4 open squares, the goal in its far corner; MiniGrid counts 40 steps."""
UP, RIGHT, DOWN, LEFT = range(4)


def recorded_grid_run() -> pd.DataFrame:
    """Three episodes of the real grid world, as the steps table records them:
    1. from (1, 1), seed 3, the oracle's six moves: the goal at step 6;
    2. from (2, 3), seed 4, one move away (left), then the oracle's four: the goal at step 5;
    3. from (1, 1), seed 3, up into the wall until the run's limit of 30 steps."""
    env = get_task("gridworld").env(GRID, 30, False)
    rows = []
    for episode, (seed, first) in enumerate(((3, []), (4, [LEFT]), (3, [UP] * 30)), start=1):
        _, info = env.reset(seed=seed)
        moves = list(first)
        n, done = 0, False
        while not done:
            action = moves.pop(0) if moves else info["correct_action"]
            _, reward, terminated, truncated, info = env.step(action)
            n += 1
            rows.append((7, episode, n, reward, terminated, "none"))
            done = terminated or truncated
    env.close()
    return pd.DataFrame(rows, columns=[*STEP_COLUMNS, "outcome"])


def test_a_recorded_grid_world_run_is_rescored_as_counted_by_hand() -> None:
    steps = recorded_grid_run()
    lengths = steps.groupby("episode")["episode_step"].max().to_dict()
    assert lengths == {1: 6, 2: 5, 3: 30}
    assert list(steps.groupby("episode")["terminated"].any()) == [True, True, False]
    # MiniGrid's reward at the goal, 1 - 0.9 x n / 40: 0.865 at step 6, 0.8875 at step 5
    logged = steps[steps["reward"] != 0]["reward"].tolist()
    assert logged == pytest.approx([0.865, 0.8875])

    totals = rescored_totals(steps, {7: "minigrid"}, task="gridworld", options={7: GRID})
    (row,) = totals.to_dict("records")
    assert row["R_T_logged"] == pytest.approx(0.865 + 0.8875)
    assert row["R_T_minigrid"] == pytest.approx(0.865 + 0.8875)  # as it was scored
    assert row["R_T_sparse"] == pytest.approx(1 + 1 + 0)  # two goals reached
    # 1 at the goal, -0.01 each other step: 5 and 4 steps before the goals, 30 without one
    assert row["R_T_step-cost"] == pytest.approx((1 - 0.05) + (1 - 0.04) - 0.30)
    assert row["not_rescored"] == ""

    first = rescored_totals(steps, {7: "minigrid"}, 1, task="gridworld", options={7: GRID})
    assert first["R_T_step-cost"].item() == pytest.approx(0.95)  # the first episode only


def test_the_grid_worlds_minigrid_score_counts_its_room_s_step_limit() -> None:
    """Back from a sparse record to MiniGrid's score: the goal's step earns what MiniGrid
    would have given there, which the run's max_steps decides."""
    task = get_task("gridworld")
    sparse = RecordedEpisode((0.0,) * 5 + (1.0,), (False,) * 5 + (True,))
    assert task.rescore(sparse, "sparse", "minigrid", GRID)[-1] == pytest.approx(0.865)
    longer = {**GRID, "max_steps": 60}
    assert task.rescore(sparse, "sparse", "minigrid", longer)[-1] == pytest.approx(0.91)
    with pytest.raises(RescoreError, match=r"no reward scheme 'paper'.*minigrid, sparse"):
        task.rescore(sparse, "paper", "sparse", GRID)


def test_a_settings_table_plans_each_sessions_scheme_and_options() -> None:
    settings = pd.DataFrame(
        {
            "session_id": [1, 2],
            "method": ["autonomous", "agent"],
            "task": ["gridworld", "gridworld"],
            "task_options": [json.dumps(GRID), json.dumps({"size": 8, "max_steps": 64})],
        }
    )
    planned = plan(settings)
    assert planned.task.name == "gridworld"
    assert planned.schemes == {1: "minigrid", 2: "minigrid"}
    assert planned.options[2] == {"size": 8, "max_steps": 64}

    sorting = pd.DataFrame(
        {
            "session_id": [3],
            "method": ["agent"],
            "task": ["sorting"],
            "task_options": ["{}"],
            "reward_scheme": ["authors-interactive"],
        }
    )
    assert plan(sorting).schemes == {3: "authors-interactive"}
    with pytest.raises(RescoreError, match="which reward scheme"):
        plan(sorting.drop(columns=["reward_scheme"]))
    with pytest.raises(RescoreError, match="different tasks \\(gridworld, sorting\\)"):
        plan(pd.concat([settings, sorting]))


def test_a_task_without_schemes_is_not_rescored_and_says_so() -> None:
    name = "tests.tasks.line:line_task"
    settings = pd.DataFrame(
        {"session_id": [1], "method": ["autonomous"], "task": [name], "task_options": ["{}"]}
    )
    with pytest.raises(RescoreError, match=f"task {name} declares no reward schemes"):
        plan(settings)
    steps = pd.DataFrame([(1, 1, 1, 0.5, True)], columns=list(STEP_COLUMNS))
    with pytest.raises(RescoreError, match="declares no reward schemes"):
        rescored_totals(steps, {1: "any"}, task=name)


@pytest.mark.slow
def test_a_recorded_reach_run_is_rescored_sparse_but_never_back_to_shaped() -> None:
    """The reach task's oracle brings the hand to the ball: shaped, each step earned up to
    0.1 (a lattice step's worth of distance) and the last 1 more; sparse, the last step 1
    and the others 0. A sparse record cannot be scored shaped: the refusal says what is
    missing."""
    task = get_task("reach")
    env = task.env({}, 50, False)
    _, info = env.reset(seed=5)
    rewards, ended = [], []
    while not ended or not ended[-1]:
        _, reward, terminated, truncated, info = env.step(info["correct_action"])
        rewards.append(reward)
        ended.append(terminated)
        assert not truncated
    env.close()
    n = len(rewards)
    assert all(0 < r <= 0.1 + 1e-9 for r in rewards[:-1]) and 1 < rewards[-1] <= 1.1 + 1e-9
    steps = pd.DataFrame(
        [(1, 1, i, r, t) for i, (r, t) in enumerate(zip(rewards, ended, strict=True), 1)],
        columns=list(STEP_COLUMNS),
    )
    (row,) = rescored_totals(steps, {1: "shaped"}, task="reach").to_dict("records")
    assert row["R_T_shaped"] == pytest.approx(sum(rewards))  # as it was scored
    assert row["R_T_sparse"] == pytest.approx(1.0)

    sparse = RecordedEpisode((0.0,) * (n - 1) + (1.0,), tuple(ended))
    with pytest.raises(RescoreError, match="distance to the ball"):
        task.rescore(sparse, "sparse", "shaped", {})
    (back,) = rescored_totals(
        steps.assign(reward=list(sparse.rewards)), {1: "sparse"}, task="reach"
    ).to_dict("records")
    assert back["R_T_sparse"] == pytest.approx(1.0) and back["R_T_shaped"] != back["R_T_shaped"]
    assert "shaped: task reach: the shaped reward counts" in back["not_rescored"]
