"""A study's data as CSV files (sessions, episodes, steps, advice with its images, the
versions of the texts participants read) and a column dictionary, written to a folder or
packed as one zip."""

from __future__ import annotations

import csv
import json
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from server.db.models import Advice, Episode, Step, StudySession, StudyTexts
from server.services.columns import column_dictionary
from server.services.studies import get_study

ACTION_NAMES = ("grab", "move right", "move left", "drop")
STEP_COLUMNS = ["session_id"] + [
    c.name for c in Step.__table__.columns if c.name not in ("id", "session_id")
]
EPISODE_COLUMNS = ["session_id"] + [
    c.name for c in Episode.__table__.columns if c.name not in ("id", "session_id")
]
SESSION_FIELDS = [
    "session_id",
    "study_id",
    "label",
    "method",
    "participant",
    "seed",
    "strategy",
    "advice_budget",
    "advisor_checkpoint",
    "oracle_error_rate",
    "motion",
    "sort_rule",
    "episodes",
    "max_episode_steps",
    "config",
    "status",
    "created_at",
    "started_at",
    "finished_at",
    "texts_version",
    "consented_at",
    "declined_at",
    "induction_done_at",
]
TEXT_KEYS = ("title", "consent", "induction_1", "induction_2", "induction_3", "thanks")
TEXTS_FIELDS = ["study_id", "texts_version", "content_hash", "created_at", *TEXT_KEYS]
ADVICE_FIELDS = [
    "session_id",
    "advice_index",
    "global_step",
    "advisor",
    "action",
    "action_name",
    "greedy_action",
    "response_time_s",
    "decision_time_s",
    "requested_at",
    "answered_at",
    "observation_file",
]
BATCH = 5000


def _write(path: Path, columns: list[str], rows: Iterable[dict[str, Any]]) -> int:
    count = 0
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow(row)
            count += 1
    return count


def _session_rows(sessions: list[StudySession]) -> Iterator[dict[str, Any]]:
    for s in sessions:
        yield {
            "session_id": s.id,
            "study_id": s.study_id,
            "label": s.label,
            "method": s.method,
            "participant": s.participant.pseudonym if s.participant else "",
            "seed": s.seed,
            "strategy": s.strategy or "",
            "advice_budget": s.advice_budget,
            "advisor_checkpoint": s.advisor_checkpoint or "",
            "oracle_error_rate": "" if s.oracle_error_rate is None else s.oracle_error_rate,
            "motion": s.motion,
            "sort_rule": json.dumps(s.sort_rule),
            "episodes": s.episodes,
            "max_episode_steps": s.max_episode_steps,
            "config": json.dumps(s.config, sort_keys=True),
            "status": s.status,
            "created_at": s.created_at.isoformat(),
            "started_at": s.started_at.isoformat() if s.started_at else "",
            "finished_at": s.finished_at.isoformat() if s.finished_at else "",
            "texts_version": s.texts_version.version if s.texts_version else "",
            "consented_at": _when(s.consented_at),
            "declined_at": _when(s.declined_at),
            "induction_done_at": _when(s.induction_done_at),
        }


def _when(value: Any) -> str:
    return value.isoformat() if value is not None else ""


def _texts_rows(db: Session, study_id: int) -> Iterator[dict[str, Any]]:
    query = select(StudyTexts).where(StudyTexts.study_id == study_id).order_by(StudyTexts.version)
    for version in db.scalars(query):
        yield {
            "study_id": version.study_id,
            "texts_version": version.version,
            "content_hash": version.content_hash,
            "created_at": version.created_at.isoformat(),
            **{key: version.texts.get(key, "") for key in TEXT_KEYS},
        }


def _records(db: Session, model: Any, ids: list[int], order: Any) -> Iterator[dict[str, Any]]:
    columns = [c for c in model.__table__.columns if c.name != "id"]
    for session_id in ids:
        query = (
            select(*columns)
            .where(model.session_id == session_id)
            .order_by(order)
            .execution_options(yield_per=BATCH)
        )
        for row in db.execute(query):
            yield dict(row._mapping)


def _advice_rows(db: Session, ids: list[int], out: Path) -> Iterator[dict[str, Any]]:
    images = out / "advice"
    images.mkdir(exist_ok=True)
    for session_id in ids:
        query = select(Advice).where(Advice.session_id == session_id).order_by(Advice.advice_index)
        for a in db.scalars(query.execution_options(yield_per=500)):
            name = f"session-{session_id}-advice-{a.advice_index:05d}.png"
            (images / name).write_bytes(a.observation_png)
            yield {
                "session_id": session_id,
                "advice_index": a.advice_index,
                "global_step": a.global_step,
                "advisor": a.advisor,
                "action": a.action,
                "action_name": ACTION_NAMES[a.action],
                "greedy_action": "" if a.greedy_action is None else a.greedy_action,
                "response_time_s": a.response_time_s,
                "decision_time_s": "" if a.decision_time_s is None else a.decision_time_s,
                "requested_at": a.requested_at.isoformat(),
                "answered_at": a.answered_at.isoformat(),
                "observation_file": f"advice/{name}",
            }


def export_study(db: Session, study_id: int, out: Path) -> dict[str, int]:
    """Write the study's files into `out`; returns the row count of each CSV."""
    study = get_study(db, study_id)
    out.mkdir(parents=True, exist_ok=True)
    sessions = list(
        db.scalars(
            select(StudySession).where(StudySession.study_id == study.id).order_by(StudySession.id)
        )
    )
    ids = [s.id for s in sessions]
    counts = {
        "sessions.csv": _write(out / "sessions.csv", SESSION_FIELDS, _session_rows(sessions)),
        "episodes.csv": _write(
            out / "episodes.csv",
            EPISODE_COLUMNS,
            _records(db, Episode, ids, Episode.first_global_step),
        ),
        "steps.csv": _write(
            out / "steps.csv", STEP_COLUMNS, _records(db, Step, ids, Step.global_step)
        ),
        "advice.csv": _write(out / "advice.csv", ADVICE_FIELDS, _advice_rows(db, ids, out)),
        "texts_versions.csv": _write(
            out / "texts_versions.csv", TEXTS_FIELDS, _texts_rows(db, study.id)
        ),
    }
    files = {
        "sessions.csv": SESSION_FIELDS,
        "episodes.csv": EPISODE_COLUMNS,
        "steps.csv": STEP_COLUMNS,
        "advice.csv": ADVICE_FIELDS,
        "texts_versions.csv": TEXTS_FIELDS,
    }
    _write(out / "columns.csv", ["file", "column", "description"], column_dictionary(files))
    (out / "study.json").write_text(
        json.dumps(
            {"id": study.id, "name": study.name, "description": study.description, "rows": counts},
            indent=2,
        )
    )
    return counts


def export_zip(db: Session, study_id: int, work_dir: Path) -> Path:
    """The study's export packed as one zip in a fresh temporary folder under `work_dir`."""
    work_dir.mkdir(parents=True, exist_ok=True)
    temp = Path(tempfile.mkdtemp(prefix=f"study-{study_id}-", dir=work_dir))
    folder = temp / f"study-{study_id}"
    export_study(db, study_id, folder)
    return Path(shutil.make_archive(str(folder), "zip", root_dir=folder))
