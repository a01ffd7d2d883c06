"""A step's Q-values are exported under its task's own action names: a grid world session's
as q_up, q_right, q_down, q_left, holding the values its learner computed; a sorting study's
steps table keeps the robot's columns exactly; a study of both tasks has both sets, each
step filling its own task's. The export reads back typed (`analysis.declared`), and its
Q-values in action order (`analysis.q_values`) from this version's export and from older
ones (the robot's four columns for any four-action task, or a JSON list)."""

from __future__ import annotations

import csv
import io
import json
import math
import zipfile
from pathlib import Path
from typing import Any

import httpx
import pandas as pd
import pytest

from analysis.declared import read_table
from analysis.q_values import read_q_values
from learner.run import RunSpec
from tests.server.scale import rest_body, wait_for_status
from tests.study.test_export_types import check_arrow_types, check_frictionless

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
SCALE: dict[str, Any] = {
    "seed": 5, "episodes": 2, "max_episode_steps": 12,
    "config": {"pretraining_steps": 16, "batch_size": 8, "memory_size": 500, "torch_threads": 1},
}  # fmt: skip
GRID = ("q_up", "q_right", "q_down", "q_left")
ROBOT = ("q_grab", "q_move_right", "q_move_left", "q_drop")
SORTING_STEP_COLUMNS = [
    "session_id", "global_step", "stage", "episode", "episode_step", "action",
    "action_source", "greedy_action", *ROBOT, "advised_action", "advice_remaining",
    "reward", "terminated", "truncated", "outcome", "epsilon", "loss", "observation_hash",
    "advised", "logged_at", "elapsed_s",
]  # fmt: skip
"""The sorting study's steps.csv header, as it has always been (the task's own names)."""


def _run(api: httpx.Client, study: int, **run: Any) -> int:
    made = api.post(f"/api/studies/{study}/sessions", json=rest_body(**SCALE, **run))
    assert made.status_code == 201, made.text
    session = int(made.json()["id"])
    assert api.post(f"/api/sessions/{session}/start").status_code == 200
    wait_for_status(api, session, {"finished"})
    return session


def _export(api: httpx.Client, study: int, fmt: str, folder: Path) -> Path:
    response = api.get(f"/api/studies/{study}/export", params={"format": fmt})
    assert response.status_code == 200, response.text
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        archive.extractall(folder)
    return folder


def _learner_q(run_spec: str) -> list[list[float]]:
    """What the learner computes for the session's run, in this process: each step's
    Q-values in action order."""
    trainer, _ = RunSpec.from_json(json.loads(run_spec)).build()
    values = []
    while not trainer.done:
        record = trainer.step()
        values.append([record.q_grab, record.q_move_right, record.q_move_left, record.q_drop])
    return values


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_a_grid_world_sessions_q_values_are_exported_under_its_actions(
    api: httpx.Client, tmp_path: Path
) -> None:
    study = api.post("/api/studies", json={"name": f"grid q {tmp_path.name}"}).json()["id"]
    session = _run(api, study, method="oracle", task="gridworld", advice_budget=6)
    folder = _export(api, study, "csv", tmp_path / "csv")
    steps = _rows(folder / "steps.csv")
    header = list(steps[0])
    assert header[8:12] == list(GRID), header
    assert not set(ROBOT) & set(header) and "q_values" not in header
    exported = _rows(folder / "sessions.csv")[0]
    assert json.loads(exported["actions"]) == ["up", "right", "down", "left"]
    run_spec = exported["run_spec"]
    computed = _learner_q(run_spec)
    assert len(steps) == len(computed) > 0
    assert [[float(s[c]) for c in GRID] for s in steps] == computed
    described = json.loads((folder / "datapackage.json").read_text())
    fields = {f["name"]: f for r in described["resources"] if r["name"] == "steps"
              for f in r["schema"]["fields"]}  # fmt: skip
    assert fields["q_left"]["type"] == "number"
    assert "action 3 of task gridworld (left)" in fields["q_left"]["description"]
    check_frictionless(folder)

    parquet = _export(api, study, "parquet", tmp_path / "parquet")
    check_arrow_types(parquet)
    for export in (folder, parquet):
        typed = read_table(export, "steps")
        assert all(str(typed[c].dtype) == "Float64" for c in GRID)
        assert typed[list(GRID)].to_numpy(dtype=float).tolist() == computed
        q = read_q_values(export)
        assert q["action_name"][:4].tolist() == ["up", "right", "down", "left"]
        assert set(q["session_id"]) == {session}
        assert q["q"].to_numpy().reshape(-1, 4).tolist() == computed


def test_a_study_of_both_tasks_exports_each_steps_own_actions(
    api: httpx.Client, tmp_path: Path
) -> None:
    study = api.post("/api/studies", json={"name": f"both q {tmp_path.name}"}).json()["id"]
    robot = _run(api, study, method="autonomous", motion="fast")
    grid = _run(api, study, method="autonomous", task="gridworld")
    folder = _export(api, study, "csv", tmp_path / "csv")
    steps = pd.read_csv(folder / "steps.csv")
    assert list(steps.columns[8:16]) == [*ROBOT, *GRID]
    for session, own, other in ((robot, ROBOT, GRID), (grid, GRID, ROBOT)):
        rows = steps[steps["session_id"] == session]
        assert len(rows) and rows[list(own)].notna().all(axis=None), session
        assert rows[list(other)].isna().all(axis=None), session
    check_frictionless(folder)
    q = read_q_values(folder)
    names = q.groupby("session_id")["action_name"].unique()
    assert names[robot].tolist() == ["grab", "move_right", "move_left", "drop"]
    assert names[grid].tolist() == ["up", "right", "down", "left"]

    sorting = api.post("/api/studies", json={"name": f"robot q {tmp_path.name}"}).json()["id"]
    robot_only = _run(api, sorting, method="autonomous", motion="fast")
    exported = _export(api, sorting, "csv", tmp_path / "robot")
    alone = pd.read_csv(exported / "steps.csv")
    assert list(alone.columns) == SORTING_STEP_COLUMNS
    both = steps[steps["session_id"] == robot][SORTING_STEP_COLUMNS[1:17]]
    assert alone[SORTING_STEP_COLUMNS[1:17]].equals(both.reset_index(drop=True)), robot_only


def test_older_exports_q_values_read_back_in_their_tasks_action_order(
    api: httpx.Client, tmp_path: Path
) -> None:
    """The 1.x fixture (the robot's four columns); a grid world's steps as the versions
    before its own names wrote them: under the robot's four columns, or as a JSON list."""
    old = read_q_values(ROOT / "tests" / "fixtures" / "export-1.x")
    steps = pd.read_csv(ROOT / "tests" / "fixtures" / "export-1.x" / "steps.csv")
    assert len(old) == 4 * len(steps) and old["action_name"][:4].tolist() == [
        "grab", "move_right", "move_left", "drop"
    ]  # fmt: skip
    assert old["q"].to_numpy().reshape(-1, 4).tolist() == steps[list(ROBOT)].to_numpy().tolist()

    study = api.post("/api/studies", json={"name": f"old q {tmp_path.name}"}).json()["id"]
    _run(api, study, method="autonomous", task="gridworld")
    folder = _export(api, study, "csv", tmp_path / "now")
    now = read_q_values(folder)
    steps = pd.read_csv(folder / "steps.csv", dtype=str, keep_default_na=False)
    as_robot = steps.rename(columns=dict(zip(GRID, ROBOT, strict=True))).assign(q_values="")
    listed = [json.dumps([float(v) for v in row]) for row in steps[list(GRID)].to_numpy()]
    as_list = steps.drop(columns=list(GRID)).assign(**dict.fromkeys(ROBOT, ""), q_values=listed)
    for name, table in (("robot", as_robot), ("list", as_list)):
        older = tmp_path / name
        older.mkdir()
        for file in ("sessions.csv", "episodes.csv", "study.json"):
            (older / file).write_bytes((folder / file).read_bytes())
        table.to_csv(older / "steps.csv", index=False)
        pd.testing.assert_frame_equal(read_q_values(older), now, obj=name)
    assert not any(math.isnan(v) for v in now["q"])
