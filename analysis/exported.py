"""A study's export read back for analysis: the runs, the episode table, the training steps
and the settings table, from the folder (or zip) that `ideeprl export` wrote, CSV or
Parquet, by this version or an older one.

Each session's run is its `run_spec` column (the whole `learner.run.RunSpec` document)
where the export has it; an export written before it (API 1.x) has one column per field,
which the run's declaration names (`Leaf.column`: `config_batch_size`, `strategy_interval`,
`oracle_error_rate`, `reward_scheme`, ...), so the run is read back from them, and fields
the export did not carry take their defaults. Old spellings of a stage (`phase`, `advice`)
read as today's (`stage`, `pretrain`).

    python -m analysis EXPORT_FOLDER_OR_ZIP OUT
"""

from __future__ import annotations

import json
import math
import tempfile
import zipfile
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.advice import ADVICE_COLUMNS, REPLAYED_ADVICE_COLUMNS
from analysis.episodes import EPISODE_TABLE_COLUMNS, arm_of
from analysis.finished import not_finished, status_of
from analysis.human import Visits
from analysis.replays import REPLAYED, unchanged_replays
from analysis.rescoring import STEP_COLUMNS
from analysis.settings import settings_table
from learner.fields import FieldError, leaves, nest
from learner.records import stage_of
from learner.run import RunSpec, declared


class ExportError(ValueError):
    """Not an export this version can read; the message says what is missing."""


@dataclass(frozen=True)
class Exported:
    """What an export holds for the analysis."""

    runs: dict[int, RunSpec]
    """Each session's run, by session id."""
    episodes: pd.DataFrame
    """Training episodes, `EPISODE_TABLE_COLUMNS`."""
    steps: pd.DataFrame
    """Training steps, `analysis.rescoring.STEP_COLUMNS` (and `outcome` when the
    export has it)."""
    settings: pd.DataFrame
    """The audit's settings table (`analysis.settings`)."""
    design: dict[str, Any] | None = None
    """An online study's design as `study.json` has it (None: a lab study, an older
    export)."""
    conditions: dict[int, str] = field(default_factory=dict)
    """An online study's condition of each session that has one, by session id."""
    advice: pd.DataFrame | None = None
    """The steps whose action came from the advisor, any stage
    (`analysis.advice.ADVICE_COLUMNS`; `outcome` missing where the export has none)."""
    name: str | None = None
    """The study's name (`study.json`; None without one)."""
    advisors: tuple[int, ...] = ()
    """Sessions left out: trained agents advising others (the export's `advises`)."""
    not_finished: dict[int, str] = field(default_factory=dict)
    """Sessions left out for not being finished (`analysis.finished`), by id: their status
    (the export's `status`)."""
    unchanged_replays: dict[int, int] = field(default_factory=dict)
    """Sessions left out: unchanged replays (`analysis.replays`), by id, with the session
    each replays (the export's `replay_of`, its source's run in the export)."""
    replayed_advice: pd.DataFrame | None = None
    """The advice rows of the replays compared (`analysis.advice.REPLAYED_ADVICE_COLUMNS`,
    from the export's advice table; None without replays or without the table)."""
    visits: Visits | None = None
    """What an online study's participants did, every visit whatever its learner's status
    (`analysis.human`; None without a design)."""

    @property
    def alpha(self) -> float:
        """The design's α (an online study), else the analysis' 0.05."""
        return float((self.design or {}).get("alpha", 0.05))


def read_export(path: Path, sessions: Collection[int] | None = None) -> Exported:
    """The export at `path` (a folder, or the zip the API serves): the sessions a report
    takes by default, as the database's report chooses them (trained advisors, unchanged
    replays and, where the export has their status, sessions not finished are left out), or
    else `sessions`, by id (any status)."""
    path = Path(path)
    if path.is_file() and zipfile.is_zipfile(path):
        with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(path) as archive:
            archive.extractall(tmp)
            return read_export(Path(tmp), sessions)
    table = every = _table(path, "sessions")
    ids = table["session_id"].astype(int)
    advisors: tuple[int, ...] = ()
    left_out: dict[int, str] = {}
    checks: dict[int, int] = {}
    if sessions is not None:
        missing = sorted(set(sessions) - set(ids))
        if missing:
            raise ExportError(
                f"session(s) {', '.join(map(str, missing))} are not in the export; its "
                f"sessions are {', '.join(map(str, sorted(ids))) or 'none'}"
            )
        table = table[ids.isin(list(sessions))]
    else:
        advisors = tuple(
            int(row["session_id"])
            for row in _rows(table)
            if "advises" in row and not _missing(row["advises"]) and _boolean(row["advises"])
        )  # older exports have no such column: their advisors stay in
        table = table[~ids.isin(advisors)]
        checks = _unchanged_replays(every, table)
        table = table[~table["session_id"].astype(int).isin(list(checks))]
        if "status" in table:  # (a table without it keeps every session)
            left_out = not_finished({int(row["session_id"]): _status(row) for row in _rows(table)})
            table = table[~table["session_id"].astype(int).isin(list(left_out))]
    runs = {int(row["session_id"]): run_of(row) for row in _rows(table)}
    episodes = _with_stage(_table(path, "episodes"))
    episodes = episodes[episodes["session_id"].isin(list(runs))]
    training = episodes[episodes["stage"] == "train"].copy()
    training["method"] = training["session_id"].map({i: arm_of(r) for i, r in runs.items()})
    training["seed"] = training["session_id"].map({i: r.seed for i, r in runs.items()})
    training = training.sort_values(["session_id", "episode"])
    every_step = _with_stage(_table(path, "steps"))
    every_step = every_step[every_step["session_id"].isin(list(runs))]
    steps = every_step[every_step["stage"] == "train"].sort_values(["session_id", "global_step"])
    design = _design(path)
    conditions = {}
    if design is not None and "condition" in table:
        conditions = {
            int(row["session_id"]): str(row["condition"])
            for row in _rows(table)
            if not _missing(row["condition"])
        }
    return Exported(
        design=design,
        conditions=conditions,
        visits=None if design is None else read_visits(path, every),
        advice=_advised(every_step),
        name=_study(path).get("name"),
        advisors=advisors,
        not_finished=left_out,
        unchanged_replays=checks,
        replayed_advice=_replayed_advice(
            path, [i for i, r in runs.items() if r.method == REPLAYED]
        ),
        runs=runs,
        episodes=training[list(EPISODE_TABLE_COLUMNS)].reset_index(drop=True),
        steps=steps[[*STEP_COLUMNS, *(["outcome"] if "outcome" in steps else [])]].reset_index(
            drop=True
        ),
        settings=settings_table(sorted(runs.items()), _provenance(table)),
    )


VISIT_COLUMNS = {
    "sessions": {"session_id": int, "condition": str, "outcome": str, "consented_at": str,
                 "status": str},
    "advice": {"session_id": int, "advisor": str, "action": float, "decision_time_s": float,
               "correct_action": float, "correct_actions": str},
    "feedback": {"session_id": int, "evaluator": str, "action": float, "judgement": float,
                 "decision_time_s": float, "correct_action": float, "correct_actions": str},
    "check": {"session_id": int, "attempt": int, "question": str, "correct": bool},
    "questionnaire": {"session_id": int, "instrument": str, "item": str,
                      "value_number": float},
    "scales": {"session_id": int, "scale": str, "score": float},
}  # fmt: skip
"""The columns of each table `analysis.human.Visits` reads, typed as the database's are
(a missing cell None, or NaN for a number); `correct_action` and `correct_actions` only where
the export has them."""


CORRECT_COLUMNS = ("correct_action", "correct_actions")
"""The visit tables' columns an export written before they were recorded lacks."""


def read_visits(path: Path, sessions: pd.DataFrame | None = None) -> Visits:
    """The participants' tables of the export folder at `path` (`sessions`: its sessions
    table, read already). A table the export lacks (one written before the visits had
    it) reads as empty."""
    frames = {}
    for name, columns in VISIT_COLUMNS.items():
        if name == "sessions" and sessions is not None:
            table = sessions
        else:
            try:
                table = _table(path, name)
            except ExportError:
                table = pd.DataFrame(columns=list(columns))
        typed = {}
        for column, kind in columns.items():
            if column not in table:
                if column in CORRECT_COLUMNS:
                    continue
                table = table.assign(**{column: None})
            typed[column] = table[column].map(lambda v, k=kind: _cell(v, k))
        frames[name] = pd.DataFrame(typed, index=table.index).reset_index(drop=True)
    for name in ("advice", "feedback", "questionnaire", "scales"):
        frame = frames[name]
        numbers = [c for c, kind in VISIT_COLUMNS[name].items() if kind is float and c in frame]
        frames[name] = frame.astype({c: "float64" for c in numbers})
    return Visits(**frames)


def _cell(value: Any, kind: type) -> Any:
    """A visit table's cell as the database gives it (None where missing)."""
    if value is pd.NA or value is pd.NaT or _missing(value):
        return None
    if kind is str:
        return str(value)
    return _typed(kind, value)


def export_of_table(path: Path) -> Path | None:
    """The export folder whose table `path` is (its episodes.csv, steps.parquet, ...), or
    None: a file beside an export's `sessions` table."""
    if not path.is_file() or path.suffix not in (".csv", ".parquet"):
        return None
    folder = path.parent
    if any((folder / f"sessions{suffix}").is_file() for suffix in (".csv", ".parquet")):
        return folder
    return None


def _unchanged_replays(every: pd.DataFrame, chosen: pd.DataFrame) -> dict[int, int]:
    """Of the `chosen` sessions, the unchanged replays of a session in the export (`every`
    session, any status): an export without `replay_of` has none."""
    if "replay_of" not in chosen:
        return {}
    replay_of = {
        int(row["session_id"]): int(float(row["replay_of"]))
        for row in _rows(chosen)
        if not _missing(row["replay_of"]) and str(row.get("method", REPLAYED)) == REPLAYED
    }
    if not replay_of:
        return {}
    rows = {int(row["session_id"]): row for row in _rows(every)}
    runs = {i: run_of(rows[i]) for i in replay_of}
    sources = {i: run_of(rows[i]) for i in set(replay_of.values()) if i in rows}
    return unchanged_replays(runs, replay_of, sources)


def _replayed_advice(path: Path, replays: list[int]) -> pd.DataFrame | None:
    """The advice rows of these replays, as the database's report reads them."""
    if not replays:
        return None
    try:
        advice = _table(path, "advice")
    except ExportError:  # an export without the advice table
        return None
    if "same_observation" not in advice:
        return None
    advice["session_id"] = pd.to_numeric(advice["session_id"]).astype("int64")
    advice = advice[advice["session_id"].isin(replays)]
    if "advice_index" in advice:
        advice = advice.assign(_i=pd.to_numeric(advice["advice_index"]))
        advice = advice.sort_values(["session_id", "_i"])
    same = advice["same_observation"].map(lambda v: None if _missing(v) else _boolean(v))
    action = advice["action"].map(lambda v: None if _missing(v) else int(float(v)))
    rows = advice.assign(same_observation=same, action=action)
    return rows[list(REPLAYED_ADVICE_COLUMNS)].reset_index(drop=True)


def _status(row: Mapping[str, Any]) -> str:
    """A session row's status as a report names it (`analysis.finished.status_of`)."""
    declined = not _missing(row.get("declined_at")) and _missing(row.get("consented_at"))
    return status_of(str(row["status"]), declined)


def run_of(row: Mapping[str, Any]) -> RunSpec:
    """A session row's run: its `run_spec` document, or its run columns (older exports)."""
    declaration = declared()
    document = row.get("run_spec")
    try:
        if isinstance(document, str) and document:
            return declaration.from_json(json.loads(document))
        values = {}
        for leaf in leaves(declaration):
            value = row.get(leaf.column)
            if _missing(value):
                continue
            values[leaf.name] = _typed(leaf.kind, value)
        if values.get("strategy") is None:
            values.pop("strategy", None)
        return declaration.from_json(nest(values, declaration))
    except (FieldError, json.JSONDecodeError) as error:
        raise ExportError(f"session {row.get('session_id')}: {error}") from None


def _provenance(sessions: pd.DataFrame) -> dict[int, list[Any]] | None:
    """Each session's provenance records (None for an export written before they were)."""
    if "provenance" not in sessions:
        return None
    return {
        int(row["session_id"]): [] if _missing(row["provenance"]) else json.loads(row["provenance"])
        for row in _rows(sessions)
    }


def _study(folder: Path) -> dict[str, Any]:
    """`study.json` (empty where the export has none)."""
    file = folder / "study.json"
    return json.loads(file.read_text()) if file.is_file() else {}


def _design(folder: Path) -> dict[str, Any] | None:
    """`study.json`'s design (None where the export has none: a lab study, older ones)."""
    design = _study(folder).get("design")
    return design if isinstance(design, dict) else None


def _advised(steps: pd.DataFrame) -> pd.DataFrame | None:
    """The advised steps of every stage, as the database's report reads them (None where the
    export names no action sources)."""
    if "action_source" not in steps or "action" not in steps:
        return None
    advised = steps[steps["action_source"] == "advisor"].sort_values(["session_id", "global_step"])
    advised = advised.assign(
        action=pd.to_numeric(advised["action"]).astype("int64"),
        outcome=advised.get("outcome"),
    )
    return advised[list(ADVICE_COLUMNS)].reset_index(drop=True)


def _table(folder: Path, name: str) -> pd.DataFrame:
    for suffix, read in ((".csv", _read_csv), (".parquet", pd.read_parquet)):
        file = folder / f"{name}{suffix}"
        if file.is_file():
            return read(file)
    raise ExportError(f"no {name}.csv or {name}.parquet in {folder}: not a study export")


def _read_csv(file: Path) -> pd.DataFrame:
    return pd.read_csv(file, dtype=str, keep_default_na=False, na_values=[""])


def _rows(table: pd.DataFrame) -> list[dict[str, Any]]:
    return [dict(row) for _, row in table.iterrows()]


def _with_stage(table: pd.DataFrame) -> pd.DataFrame:
    """Today's `stage` column from an export's `stage` or older `phase`, numbers typed."""
    table = table.rename(columns={"phase": "stage"})
    if "stage" not in table:
        raise ExportError("the export's steps and episodes have no stage (or phase) column")
    table["stage"] = table["stage"].map(stage_of)
    for column in ("session_id", "episode", "episode_step", "global_step", "steps",
                   "placed_correct", "misplaced", "lost"):  # fmt: skip
        if column in table:
            table[column] = pd.to_numeric(table[column]).astype("int64")
    for column in ("collected_reward", "epsilon", "reward"):
        if column in table:
            table[column] = pd.to_numeric(table[column]).astype("float64")
    for column in ("terminated", "success"):
        if column in table:
            table[column] = table[column].map(_boolean)
    return table


def _missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value)) or value == ""


def _boolean(value: Any) -> bool:
    return value if isinstance(value, bool) else str(value).lower() == "true"


def _typed(kind: type, value: Any) -> Any:
    """A cell as its field's type (CSV cells are text; Parquet's are typed already)."""
    if hasattr(value, "item"):  # a numpy scalar from Parquet
        value = value.item()
    if kind is bool:
        return _boolean(value)
    if kind is int:
        return int(float(value)) if isinstance(value, str) else int(value)
    if kind is float:
        return float(value)
    return value
