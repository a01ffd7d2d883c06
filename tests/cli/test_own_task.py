"""A researcher's own task from outside the package (docs/examples/catch), named as
module:callable with its folder on PYTHONPATH, as the README says: a batch of autonomous
and oracle-advised agents runs it in worker processes, and the export reads back with its
three actions' Q-values under their own names."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.q_values import read_q_values

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
CATCH = ROOT / "docs" / "examples" / "catch"
SCALE = ["--episodes", "2", "--pretraining-steps", "40", "--advice-budget", "10",
         "--max-episode-steps", "20", "--set", "batch_size=8", "--set", "memory_size=200",
         "--torch-threads", "1"]  # fmt: skip


def ideeprl(*args: str, data: Path, task_path: bool = True) -> subprocess.CompletedProcess[str]:
    paths = [str(CATCH), str(ROOT)] if task_path else [str(ROOT)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
    return subprocess.run(
        [sys.executable, "-m", "cli", *args, "--data-dir", str(data)],
        capture_output=True, text=True, env=env, cwd=ROOT, timeout=600,
    )  # fmt: skip


def test_a_researchers_own_task_runs_a_batch_and_exports(tmp_path: Path) -> None:
    data = tmp_path / "data"
    batch = ideeprl("batch", "--study", "catch", "--task", "catch:catch_task",
                    "--task-options", '{"paddle_width": 4}', "--methods", "autonomous",
                    "oracle", "--agents", "1", "--no-progress", *SCALE, data=data)  # fmt: skip
    assert batch.returncode == 0, batch.stderr
    exported = ideeprl("export", "--study", "catch", "--out", str(tmp_path / "out"), data=data)
    assert exported.returncode == 0, exported.stderr
    with open(tmp_path / "out" / "sessions.csv") as f:
        sessions = list(csv.DictReader(f))
    assert len(sessions) == 2 and {s["task"] for s in sessions} == {"catch:catch_task"}
    with open(tmp_path / "out" / "steps.csv") as f:
        steps = list(csv.DictReader(f))
    q = ("q_left", "q_stay", "q_right")  # its actions' own names
    assert steps and [c for c in steps[0] if c.startswith("q_")] == list(q)
    assert all(float(s[c]) == float(s[c]) for s in steps for c in q)  # every one a number
    assert {int(s["action"]) for s in steps} <= {0, 1, 2}
    values = read_q_values(tmp_path / "out")
    assert values["action_name"][:3].tolist() == ["left", "stay", "right"]

    # exported by a process that cannot import the task: its actions numbered, same values
    blind = ideeprl("export", "--study", "catch", "--out", str(tmp_path / "blind"), data=data,
                    task_path=False)  # fmt: skip
    assert blind.returncode == 0, blind.stderr
    with open(tmp_path / "blind" / "steps.csv") as f:
        numbered = list(csv.DictReader(f))
    q_numbered = [f"q_action_{i}" for i in range(3)]
    assert [c for c in numbered[0] if c.startswith("q_")] == q_numbered
    assert [[s[c] for c in q_numbered] for s in numbered] == [[s[c] for c in q] for s in steps]
    again = read_q_values(tmp_path / "blind")
    assert again["q"].tolist() == values["q"].tolist()

    wrong = ideeprl("batch", "--study", "catch", "--task", "catch:no_such_task",
                    "--methods", "autonomous", "--agents", "1", *SCALE, data=data)  # fmt: skip
    assert wrong.returncode != 0 and "catch:no_such_task" in wrong.stderr
