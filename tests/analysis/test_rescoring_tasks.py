"""Rescoring goes through the task: the grid world's and the reach task's recorded runs are
rescored under their own schemes, checked against sums done by hand, and a study of two
tasks task by task; a task without schemes, or a scheme the record cannot give, is refused
with the reason, never a number."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from analysis.rescoring import (
    STEP_COLUMNS,
    plan,
    rescored_by_task,
    rescored_totals,
    rescoring_table,
)
from sim.rewards import REWARD_SCHEMES, step_penalty
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
    (planned,) = plan(settings).tasks
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
    assert plan(sorting).tasks[0].schemes == {3: "authors-interactive"}
    with pytest.raises(RescoreError, match="which reward scheme"):
        plan(sorting.drop(columns=["reward_scheme"]))

    mixed = plan(pd.concat([settings, sorting]))
    assert [(p.task.name, p.schemes) for p in mixed.tasks] == [
        ("gridworld", {1: "minigrid", 2: "minigrid"}),
        ("sorting", {3: "authors-interactive"}),
    ]
    assert mixed.not_rescored == {}
    assert mixed.schemes == ("minigrid", "sparse", "step-cost", *REWARD_SCHEMES)
    # the grid world is rescored, the sorting robot's sessions (scheme unsaid) are not
    unsaid = plan(pd.concat([settings, sorting.drop(columns=["reward_scheme"])]))
    assert [p.task.name for p in unsaid.tasks] == ["gridworld"]
    assert "session 3 of task sorting" in unsaid.not_rescored["sorting"]


def recorded_sorting_run() -> pd.DataFrame:
    """Session 8 of the sorting robot, one 25-step episode scored under the authors'
    interactive scheme: placements at steps 3, 6 and 24 (0.4 each), a misplacement at 25
    (-1, which ends it), every other step costing what the scheme says (as in
    tests/sim/test_rewards.py); the steps' outcomes recorded."""
    placed = {3: 0.4, 6: 0.4, 24: 0.4, 25: -1.0}
    outcome = {3: "placed", 6: "placed", 24: "placed", 25: "misplaced"}
    rows = [
        (8, 1, n, placed.get(n, step_penalty("authors-interactive", n)), n == 25,
         outcome.get(n, "none"))
        for n in range(1, 26)
    ]  # fmt: skip
    return pd.DataFrame(rows, columns=[*STEP_COLUMNS, "outcome"])


def test_a_study_of_two_tasks_is_rescored_task_by_task() -> None:
    """The grid world's session under the grid world's schemes, the sorting robot's under
    the robot's, as each is counted alone; a scheme a session's task does not declare is
    left empty and named, never refused for the study."""
    steps = pd.concat([recorded_grid_run(), recorded_sorting_run()], ignore_index=True)
    settings = pd.DataFrame(
        {
            "session_id": [7, 8],
            "method": ["autonomous", "autonomous"],
            "task": ["gridworld", "sorting"],
            "task_options": [json.dumps(GRID), "{}"],
            "reward_scheme": [None, "authors-interactive"],
        }
    )
    totals = rescored_by_task(steps, plan(settings)).set_index("session_id")
    grid = totals.loc[7]
    assert grid["task"] == "gridworld" and grid["scheme"] == "minigrid"
    assert grid["R_T_sparse"] == pytest.approx(2)
    assert grid["R_T_step-cost"] == pytest.approx((1 - 0.05) + (1 - 0.04) - 0.30)
    assert all(grid[f"R_T_{s}"] != grid[f"R_T_{s}"] for s in REWARD_SCHEMES)  # NaN
    assert grid["undeclared"] == ", ".join(REWARD_SCHEMES) and grid["not_rescored"] == ""
    robot = totals.loc[8]
    assert robot["task"] == "sorting" and robot["scheme"] == "authors-interactive"
    # by hand (tests/sim/test_rewards.py): paper 0.15, autonomous 0.10, interactive -0.01
    assert robot["R_T_paper"] == pytest.approx(0.15)
    assert robot["R_T_authors-autonomous"] == pytest.approx(0.10)
    assert robot["R_T_authors-interactive"] == pytest.approx(-0.01)
    assert robot["undeclared"] == "minigrid, sparse, step-cost" and robot["not_rescored"] == ""
    assert all(robot[f"R_T_{s}"] != robot[f"R_T_{s}"] for s in ("minigrid", "sparse"))
    alone = rescored_totals(recorded_sorting_run(), {8: "authors-interactive"})
    assert alone["R_T_paper"].item() == pytest.approx(robot["R_T_paper"])

    table = rescoring_table(totals.reset_index(), {7: "autonomous", 8: "autonomous"})
    assert list(table["task"]) == ["gridworld", "sorting"]
    rows = table.set_index("task")
    assert rows.loc["gridworld", "R_T_sparse"] == pytest.approx(2)
    assert rows.loc["sorting", "R_T_paper"] == pytest.approx(0.15)
    assert rows.loc["sorting", "R_T_sparse"] != rows.loc["sorting", "R_T_sparse"]  # NaN


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
