"""`ideeprl train`'s steps.csv names a step's Q-values by its task's actions, as the study
export does: a grid world run's values under q_up, q_right, q_down, q_left, those the
learner computed; a resumed run's file, written with the values under the robot's four
names, reads on under the task's."""

from __future__ import annotations

import csv
from pathlib import Path

from learner.recording import CsvRecorder
from learner.run import RunSpec

GRID = ["q_up", "q_right", "q_down", "q_left"]
ROBOT = ["q_grab", "q_move_right", "q_move_left", "q_drop"]


def _grid_run(out: Path) -> list[list[float | None]]:
    """A small grid world run recorded into `out`; each step's Q-values as computed."""
    spec = RunSpec.from_json(
        {"task": "gridworld", "method": "oracle", "seed": 3,
         "config": {"episodes": 2, "pretraining_steps": 16, "advice_budget": 6,
                    "batch_size": 8, "memory_size": 300, "max_episode_steps": 12,
                    "torch_threads": 1}}
    )  # fmt: skip
    recorder = CsvRecorder(out, actions=spec.the_task.action_names)
    trainer, _ = spec.build([recorder])
    computed = []
    while not trainer.done:
        r = trainer.step()
        computed.append([r.q_grab, r.q_move_right, r.q_move_left, r.q_drop])
    recorder.close()
    return computed


def _rows(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def test_a_grid_world_runs_steps_csv_has_its_actions_q_values(tmp_path: Path) -> None:
    computed = _grid_run(tmp_path)
    header, rows = _rows(tmp_path / "steps.csv")
    assert header[6:11] == ["greedy_action", *GRID] and not set(ROBOT) & set(header)
    assert "q_values" not in header
    assert [[float(r[c]) for c in GRID] for r in rows] == computed


def test_a_resumed_file_of_positional_q_values_is_named_by_its_task(tmp_path: Path) -> None:
    _grid_run(tmp_path)
    header, rows = _rows(tmp_path / "steps.csv")
    named = [[r[c] for c in GRID] for r in rows]
    positional = [c if c not in GRID else ROBOT[GRID.index(c)] for c in header] + ["q_values"]
    with (tmp_path / "steps.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=positional, extrasaction="ignore")
        writer.writeheader()
        writer.writerows({**r, **dict(zip(ROBOT, q, strict=True)), "q_values": ""}
                         for r, q in zip(rows, named, strict=True))  # fmt: skip
    last = int(rows[9]["global_step"])
    CsvRecorder(tmp_path, resume_from_step=last, actions=("up", "right", "down", "left")).close()
    again, kept = _rows(tmp_path / "steps.csv")
    assert again == header and len(kept) == 10
    assert [[r[c] for c in GRID] for r in kept] == named[:10]
