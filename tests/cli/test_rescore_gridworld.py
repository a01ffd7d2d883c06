"""A grid world batch, recorded by the platform, is rescored by `ideeprl report` under the
grid world's own schemes (never the sorting robot's), each agent's R_T as counted by hand
from the exported steps: where each training episode reached the goal; a study of the grid
world and the sorting robot is rescored task by task."""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

import pytest

from sim.rewards import REWARD_SCHEMES, step_penalty
from tests import in_process

pytestmark = pytest.mark.slow

OPTIONS = {"size": 5, "max_steps": 30}
"""A room of 3 x 3 open squares, whose MiniGrid score counts 30 steps."""
GRID_SCHEMES = ("minigrid", "sparse", "step-cost")
SCALE = ["--episodes", "4", "--pretraining-steps", "40", "--advice-budget", "10",
         "--max-episode-steps", "30", "--set", "batch_size=8", "--set", "memory_size=200",
         "--torch-threads", "1"]  # fmt: skip


def ideeprl(*args: str, data: Path) -> subprocess.CompletedProcess[str]:
    """`ideeprl ARGS --data-dir DATA` in the test's process (its batch's workers are
    processes all the same)."""
    return in_process.ideeprl(*args, "--data-dir", str(data))


def by_hand(steps: list[dict[str, str]]) -> dict[int, dict[str, float]]:
    """Each session's R_T under the three schemes, from where its training episodes ended:
    at the goal at step n, MiniGrid gives 1 - 0.9 x n / 30, sparse 1, step-cost 1 less
    0.01 for each of the n - 1 steps before; an episode that never got there, 0, 0 and
    0.01 for each of its steps."""
    episodes: dict[tuple[int, int], tuple[int, bool]] = {}
    for step in steps:
        if step["stage"] != "train":
            continue
        key = (int(step["session_id"]), int(step["episode"]))
        n, reached = int(step["episode_step"]), step["terminated"] == "true"
        before = episodes.get(key, (0, False))
        episodes[key] = (max(n, before[0]), reached or before[1])
    totals: dict[int, dict[str, float]] = {}
    for (session, _), (n, reached) in episodes.items():
        total = totals.setdefault(session, {"minigrid": 0.0, "sparse": 0.0, "step-cost": 0.0})
        if reached:
            total["minigrid"] += 1 - 0.9 * n / OPTIONS["max_steps"]
            total["sparse"] += 1
            total["step-cost"] += 1 - 0.01 * (n - 1)
        else:
            total["step-cost"] -= 0.01 * n
    return totals


def test_a_grid_world_batch_is_rescored_under_its_own_schemes(tmp_path: Path) -> None:
    data = tmp_path / "data"
    batch = ideeprl("batch", "--study", "grid", "--task", "gridworld",
                    "--task-options", json.dumps(OPTIONS), "--methods", "autonomous",
                    "oracle", "--agents", "1", "--no-progress", *SCALE, data=data)  # fmt: skip
    assert batch.returncode == 0, batch.stderr
    report = ideeprl("report", "--study", "grid", "--out", str(tmp_path / "report"), data=data)
    assert report.returncode == 0, report.stderr
    exported = ideeprl("export", "--study", "grid", "--out", str(tmp_path / "out"), data=data)
    assert exported.returncode == 0, exported.stderr

    with open(tmp_path / "out" / "steps.csv") as f:
        expected = by_hand(list(csv.DictReader(f)))
    with open(tmp_path / "report" / "r_t_rescored_per_agent.csv") as f:
        rescored = {int(r["session_id"]): r for r in csv.DictReader(f)}
    assert set(rescored) == set(expected) and len(expected) == 2
    for session, hand in expected.items():
        row = rescored[session]
        assert row["scheme"] == "minigrid" and row["not_rescored"] == ""
        assert float(row["R_T_logged"]) == pytest.approx(hand["minigrid"])
        for scheme, value in hand.items():
            assert float(row[f"R_T_{scheme}"]) == pytest.approx(value), (session, scheme)
    text = (tmp_path / "report" / "report.md").read_text()
    assert "R_T under step-cost" in text and "authors-interactive" not in text


def robot_by_hand(steps: list[dict[str, str]]) -> dict[int, dict[str, float]]:
    """Each sorting session's R_T under the robot's three schemes, from its exported
    training steps: a step that placed an object (right or wrong) keeps its reward, every
    other step costs what the scheme says at its number in the episode."""
    totals: dict[int, dict[str, float]] = {}
    for step in steps:
        if step["stage"] != "train":
            continue
        total = totals.setdefault(int(step["session_id"]), dict.fromkeys(REWARD_SCHEMES, 0.0))
        for scheme in REWARD_SCHEMES:
            if step["outcome"] in ("placed", "misplaced"):
                total[scheme] += float(step["reward"])
            else:
                total[scheme] += step_penalty(scheme, int(step["episode_step"]))
    return totals


def test_a_study_of_the_grid_world_and_the_sorting_robot_is_rescored_task_by_task(
    tmp_path: Path,
) -> None:
    """One study, two batches: the grid world's and the sorting robot's. The report (from
    the database, and from the study's export) rescores each session under its own task's
    schemes, as counted by hand from the exported steps, leaves the other task's schemes
    empty and named, and says which task was rescored under which schemes."""
    data = tmp_path / "data"
    grid = ideeprl("batch", "--study", "mixed", "--task", "gridworld",
                   "--task-options", json.dumps(OPTIONS), "--methods", "autonomous",
                   "oracle", "--agents", "1", "--no-progress", *SCALE, data=data)  # fmt: skip
    assert grid.returncode == 0, grid.stderr
    robot = ideeprl("batch", "--study", "mixed", "--methods", "autonomous", "--agents", "1",
                    "--no-progress", *SCALE, data=data)  # fmt: skip
    assert robot.returncode == 0, robot.stderr
    exported = ideeprl("export", "--study", "mixed", "--out", str(tmp_path / "out"), data=data)
    assert exported.returncode == 0, exported.stderr
    with open(tmp_path / "out" / "steps.csv") as f:
        steps = list(csv.DictReader(f))
    with open(tmp_path / "out" / "sessions.csv") as f:
        runs = {int(r["session_id"]): json.loads(r["run_spec"]) for r in csv.DictReader(f)}
    tasks = {session: run.get("task", "sorting") for session, run in runs.items()}
    grid_hand = by_hand([s for s in steps if tasks[int(s["session_id"])] == "gridworld"])
    robot_hand = robot_by_hand([s for s in steps if tasks[int(s["session_id"])] == "sorting"])
    assert len(grid_hand) == 2 and len(robot_hand) == 1

    report = ideeprl("report", "--study", "mixed", "--out", str(tmp_path / "db"), data=data)
    assert report.returncode == 0, report.stderr
    from_files = in_process.analysis(str(tmp_path / "out"), str(tmp_path / "files"))
    assert from_files.returncode == 0, from_files.stderr
    for folder in ("db", "files"):
        with open(tmp_path / folder / "r_t_rescored_per_agent.csv") as f:
            rescored = {int(r["session_id"]): r for r in csv.DictReader(f)}
        assert set(rescored) == set(grid_hand) | set(robot_hand)
        for session, hand in [*grid_hand.items(), *robot_hand.items()]:
            row = rescored[session]
            assert row["task"] == tasks[session] and row["not_rescored"] == ""
            for scheme, value in hand.items():
                assert float(row[f"R_T_{scheme}"]) == pytest.approx(value), (folder, session)
            others = [s for s in (*REWARD_SCHEMES, *GRID_SCHEMES) if s not in hand]
            assert all(row[f"R_T_{s}"] == "" for s in others), row
            assert row["undeclared"] == ", ".join(others)
        text = (tmp_path / folder / "report.md").read_text()
        rescoring = text.split("## R_T rescored under each reward scheme")[1].split("\n## ")[0]
        assert "gridworld under minigrid, sparse, step-cost" in rescoring, rescoring
        assert f"sorting under {', '.join(REWARD_SCHEMES)}" in rescoring
        assert "| gridworld |" in rescoring and "| sorting |" in rescoring
