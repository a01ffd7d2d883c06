"""A study export's Q-values read back: each step's value of each action of its session's
task, named as the task names its actions, from an export of this version or an older one.

Long, one row per step and action, because a study may run tasks with different actions:
`session_id`, `global_step`, `stage`, `action` (its index, the learner's output),
`action_name` (`tasks.Task.action_names`) and `q`.

What each version wrote: this one, a column `q_<action name>` per action of the session's
task (`study.services.export`), the names listed in the sessions table's `actions`; older
ones, the four columns `q_grab`, `q_move_right`, `q_move_left`, `q_drop` holding actions
0-3 of any task with four actions (the sorting robot's, but a grid world's too), and a task
with another number of actions its values in `q_values` (a JSON list in action order).
Their sessions have no `actions`: the names are the task's where this process can load it,
else numbered (action_0, action_1, ...).
"""

from __future__ import annotations

import json
import tempfile
import zipfile
from collections.abc import Collection
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.exported import ExportError, _rows, _table, _with_stage, run_of
from tasks import TaskError, get_task

FOUR = ("q_grab", "q_move_right", "q_move_left", "q_drop")
"""An older export's columns of a four-action task's Q-values, actions 0-3."""
Q_COLUMNS = {
    "session_id": "int64",
    "global_step": "int64",
    "stage": "object",
    "action": "int64",
    "action_name": "object",
    "q": "float64",
}
"""The columns of `read_q_values`' table, with their dtypes."""


def read_q_values(export: str | Path, sessions: Collection[int] | None = None) -> pd.DataFrame:
    """Every step's Q-values of the export at `export`, a folder or its zip (of `sessions`
    only, by id, when given), `Q_COLUMNS`, by session, step and action. `ExportError` where
    a session's steps carry none of the forms above."""
    folder = Path(export)
    if folder.is_file() and zipfile.is_zipfile(folder):
        with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(folder) as archive:
            archive.extractall(tmp)
            return read_q_values(Path(tmp), sessions)
    sessions_table = _rows(_table(folder, "sessions"))
    runs = {int(row["session_id"]): run_of(row) for row in sessions_table}
    declared = {
        int(row["session_id"]): tuple(json.loads(row["actions"]))
        for row in sessions_table
        if isinstance(row.get("actions"), str) and row["actions"]
    }
    steps = _with_stage(_table(folder, "steps"))
    if sessions is not None:
        steps = steps[steps["session_id"].isin(list(sessions))]
    frames = []
    for session_id, rows in steps.sort_values(["session_id", "global_step"]).groupby("session_id"):
        run = runs.get(int(session_id))
        if run is None:
            raise ExportError(f"steps of session {session_id}, which sessions does not have")
        names, values = _session_q(rows, run.task, int(session_id), declared.get(int(session_id)))
        long = pd.DataFrame(
            {
                "session_id": rows["session_id"].repeat(len(names)).to_numpy(),
                "global_step": rows["global_step"].repeat(len(names)).to_numpy(),
                "stage": rows["stage"].repeat(len(names)).to_numpy(),
                "action": list(range(len(names))) * len(rows),
                "action_name": list(names) * len(rows),
                "q": values.reshape(-1),
            }
        )
        frames.append(long)
    if not frames:
        return pd.DataFrame({c: pd.Series(dtype=t) for c, t in Q_COLUMNS.items()})
    return pd.concat(frames, ignore_index=True).astype(Q_COLUMNS)


def _session_q(
    rows: pd.DataFrame, task: str, session_id: int, actions: tuple[str, ...] | None
) -> tuple[tuple[str, ...], np.ndarray]:
    """One session's action names (`actions`, as the export's sessions table lists them;
    None: as its task names them) and its steps' Q-values (steps x actions)."""
    names: tuple[str, ...] | None = actions
    if names is None:
        try:
            names = get_task(task).action_names
        except TaskError:  # a researcher's module this process cannot import: numbered
            names = None
    own = () if names is None else tuple(f"q_{n}" for n in names)
    if own and all(c in rows and rows[c].notna().all() for c in own):
        values = rows[list(own)].apply(pd.to_numeric)
        return tuple(c[2:] for c in own), values.to_numpy(dtype=float)
    if "q_values" in rows and rows["q_values"].notna().all():
        listed = [json.loads(v) for v in rows["q_values"]]
        count = len(listed[0])
        names = names or tuple(f"action_{i}" for i in range(count))
        if all(len(v) == len(names) for v in listed):
            return names, pd.DataFrame(listed).to_numpy(dtype=float)
    if all(c in rows and rows[c].notna().all() for c in FOUR) and len(names or FOUR) == 4:
        names = names or tuple(f"action_{i}" for i in range(4))
        return names, rows[list(FOUR)].apply(pd.to_numeric).to_numpy(dtype=float)
    raise ExportError(
        f"session {session_id} (task {task}): its steps have no Q-values for the task's "
        f"{len(names) if names else 'unknown'} actions"
    )
