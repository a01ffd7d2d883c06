"""A study's data, ready for analysis: sessions, episodes, steps, advice (with the
advised images) and evaluative feedback as CSV or Parquet, described by a Frictionless
`datapackage.json` (each column's type, unit and description) and the same dictionary as
`columns.csv`; written to a folder or packed as one zip.

Analysis-ready means: ISO 8601 UTC timestamps (`logged_at`, with `elapsed_s` since the
session started beside it), lowercase booleans, the sort rule as plain text, the learner
config as one column per field, each episode's reset seed (replay it with the episode's
actions), one stage vocabulary in steps and episodes (`stage`: `pretrain`, `train`; a
pretraining step taken on advice has `action_source` advisor and `advised = true`), and
each session's run both as
columns (one per field of `learner.run.RunSpec`) and whole (`run_spec`, JSON: what the API
and `ideeprl batch` accept back). An online study adds its assignments and its
participants' panel ids (pseudonymous unless asked for, for payment); a researcher's
previews are never exported.

A step's Q-values are one column per action of its session's task, named by the task
(`q_grab`, `q_move_right`, ... for the sorting robot; `q_up`, `q_right`, ... in the grid
world). A study of several tasks keeps one steps table whose Q-value columns are the union
of its tasks' (in the order its sessions first run them): each step fills its own task's
and leaves the others empty, and tasks that name an action alike share its column. The
sessions table's `actions` lists each session's action names in order.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from analysis.settings import where
from learner.fields import leaves
from learner.records import STORED_Q, named_q
from learner.run import RunSpecError, declared
from sim.rules import SortRule
from study.db.models import (
    Advice,
    Assignment,
    Episode,
    Feedback,
    PanelId,
    Participant,
    Step,
    Study,
    StudySession,
    StudyTexts,
)
from study.services import visit_export
from study.services.columns import TEXT_KEYS, QActions, table_columns
from study.services.errors import Conflict
from study.services.sessions import advisor_sessions
from study.services.studies import get_study
from study.services.tables import column, resource, write_csv, write_parquet
from tasks import actions_text

FORMATS = ("csv", "parquet")
TABLES = (
    "sessions",
    "episodes",
    "steps",
    "advice",
    "feedback",
    "texts_versions",
    "assignments",
    "panel_ids",
    *visit_export.KEYS,
)
KEYS: dict[str, dict[str, Any]] = {
    "sessions": {"primaryKey": ["session_id"]},
    "episodes": {"primaryKey": ["session_id", "stage", "episode"]},
    "steps": {"primaryKey": ["session_id", "global_step"]},
    "advice": {"primaryKey": ["session_id", "advice_index"]},
    "feedback": {"primaryKey": ["session_id", "feedback_index"]},
    "texts_versions": {"primaryKey": ["study_id", "texts_version"]},
    "assignments": {"primaryKey": ["session_id"]},
    "panel_ids": {"primaryKey": ["participant"]},
    **visit_export.KEYS,
}
BATCH = 5000
DICTIONARY_COLUMNS = [
    column("file", "string", "The table."),
    column("column", "string", "The column."),
    column("type", "string", "Its Frictionless Table Schema type."),
    column("unit", "string", "Its unit, for a quantity."),
    column("description", "string", "What it means."),
]


def plain_sort_rule(spec: str | dict[str, str]) -> str:
    """`color`, `shape`, or `cube/red=left;cube/blue=right;...` for an explicit map."""

    rule = SortRule.parse(spec)
    if rule.name != "map":
        return rule.name
    return ";".join(f"{shape}/{color}={side}" for shape, color, side in rule.sides)


def _cell_value(value: Any) -> Any:
    """A run field's value as one cell: a mapping (a task's options) as JSON with sorted keys,
    as its declared `string` column holds it in CSV and Parquet alike."""
    return json.dumps(value, sort_keys=True) if isinstance(value, dict) else value


def _session_rows(
    sessions: list[StudySession], actions: dict[int, QActions]
) -> Iterator[dict[str, Any]]:
    run_leaves = leaves(declared())
    advisors = advisor_sessions(sessions)
    for s in sessions:
        values = s.spec.values()
        values["sort_rule"] = plain_sort_rule(values["sort_rule"])
        yield {
            "session_id": s.id,
            "study_id": s.study_id,
            "label": s.label,
            **{leaf.column: _cell_value(values[leaf.name]) for leaf in run_leaves},
            "participant": s.participant.pseudonym if s.participant else None,
            "status": s.status,
            "created_at": s.created_at,
            "started_at": s.started_at,
            "finished_at": s.finished_at,
            "texts_version": s.texts_version.version if s.texts_version else None,
            "consented_at": s.consented_at,
            "declined_at": s.declined_at,
            "induction_done_at": s.induction_done_at,
            "numerics_overrides": json.dumps(s.numerics_overrides)
            if s.numerics_overrides
            else None,
            "code_version": where(s.provenance, "code") if s.provenance else None,
            "provenance": json.dumps(s.provenance) if s.provenance else None,
            "replay_of": s.replay_of,
            "condition": s.condition,
            "outcome": s.outcome,
            "outcome_at": s.outcome_at,
            "advises": s.id in advisors,
            "replay_source": json.dumps(s.replay_stream["source"], sort_keys=True)
            if s.replay_stream
            else None,
            "actions": json.dumps(list(actions[s.id].names)),
            "run_spec": json.dumps(s.run, sort_keys=True),
        }


def _records(
    db: Session,
    model: Any,
    sessions: list[StudySession],
    order: Any,
    q: dict[int, QActions] | None = None,
) -> Iterator[dict[str, Any]]:
    """The session's records, in `order`; a step's Q-values named by `q`, its session's
    task's actions."""
    from datetime import UTC, datetime

    columns = [c for c in model.__table__.columns if c.name != "id"]
    for session in sessions:
        started = session.started_at.timestamp() if session.started_at else None
        query = (
            select(*columns)
            .where(model.session_id == session.id)
            .order_by(order)
            .execution_options(yield_per=BATCH)
        )
        for found in db.execute(query):
            row = dict(found._mapping)
            wall = row.pop("wall_time")
            row["logged_at"] = datetime.fromtimestamp(wall, UTC)
            row["elapsed_s"] = None if started is None else round(wall - started, 3)
            if model is Step:
                row["advised"] = row["advised_action"] is not None
                row |= _named_q(row, (q or {})[session.id], session)
            yield row


def _named_q(row: dict[str, Any], actions: QActions, session: StudySession) -> dict[str, Any]:
    """A stored step's Q-values (taken out of `row`) as its task's columns."""
    stored = {name: row.pop(name) for name in STORED_Q}
    try:
        return named_q(stored, actions.names)
    except ValueError as error:
        raise Conflict(
            f"session {session.id} (task {session.spec.task}): {error}; export it with the "
            "task module it ran with"
        ) from None


def _q_actions(
    db: Session, sessions: list[StudySession]
) -> tuple[dict[int, QActions], dict[str, QActions]]:
    """Each session's task's actions, by session id, and each task's, by name, in the order
    of the sessions. A task this process cannot load (a researcher's module it cannot
    import) has its actions numbered, as many as its first stored step has Q-values."""
    tasks = {session.id: session.spec for session in sessions}
    by_task: dict[str, QActions] = {}
    for spec in tasks.values():
        if spec.task in by_task:
            continue
        try:
            by_task[spec.task] = QActions.of(spec.the_task)
        except RunSpecError:
            ids = [i for i, other in tasks.items() if other.task == spec.task]
            query = select(Step.q_values).where(Step.session_id.in_(ids)).limit(1)
            listed = db.scalars(query).first()  # None: four actions (or no step yet)
            by_task[spec.task] = QActions.numbered(4 if listed is None else len(json.loads(listed)))
    return {i: by_task[spec.task] for i, spec in tasks.items()}, by_task


def _action_words(session: StudySession) -> tuple[str, ...]:
    """The session's actions in its task's words; none where its task cannot be had here
    (a researcher's module not importable by this process: the export then leaves the
    names empty rather than failing)."""
    try:
        return session.spec.the_task.action_words
    except RunSpecError:
        return ()


def _advice_rows(db: Session, sessions: list[StudySession], out: Path) -> Iterator[dict[str, Any]]:
    images = out / "advice"
    images.mkdir(exist_ok=True)
    for session in sessions:
        query = select(Advice).where(Advice.session_id == session.id)
        words = _action_words(session)
        for a in db.scalars(query.order_by(Advice.advice_index).execution_options(yield_per=500)):
            name = f"session-{session.id}-advice-{a.advice_index:05d}.png"
            (images / name).write_bytes(a.observation_png)
            yield {
                "session_id": session.id,
                "advice_index": a.advice_index,
                "global_step": a.global_step,
                "advisor": a.advisor,
                "action": a.action,
                "action_name": words[a.action]
                if a.action is not None and a.action < len(words)
                else None,
                "greedy_action": a.greedy_action,
                "response_time_s": a.response_time_s,
                "decision_time_s": a.decision_time_s,
                "requested_at": a.requested_at,
                "answered_at": a.answered_at,
                "observation_file": f"advice/{name}",
                "same_observation": a.same_observation,
                "correct_action": a.correct_action,
                "correct_actions": actions_text(a.correct_actions),
            }


def _feedback_rows(db: Session, sessions: list[StudySession]) -> Iterator[dict[str, Any]]:
    """Evaluative feedback's judgements, session by session, in the order given; each
    action named in its run's task's words."""
    for session in sessions:
        query = select(Feedback).where(Feedback.session_id == session.id)
        words = _action_words(session)
        for f in db.scalars(query.order_by(Feedback.feedback_index)):
            yield {
                "session_id": session.id,
                "feedback_index": f.feedback_index,
                "global_step": f.global_step,
                "evaluator": f.evaluator,
                "action": f.action,
                "action_name": words[f.action] if f.action < len(words) else None,
                "judgement": f.judgement,
                "shaping": f.shaping,
                "greedy_action": f.greedy_action,
                "observation_hash": f.observation_hash,
                "response_time_s": f.response_time_s,
                "decision_time_s": f.decision_time_s,
                "requested_at": f.requested_at,
                "answered_at": f.answered_at,
                "correct_action": f.correct_action,
                "correct_actions": actions_text(f.correct_actions),
            }


def _texts_rows(db: Session, study_id: int) -> Iterator[dict[str, Any]]:
    """Each distinct version of the study's texts that a participant was shown."""
    query = select(StudyTexts).where(StudyTexts.study_id == study_id).order_by(StudyTexts.version)
    for version in db.scalars(query):
        yield {
            "study_id": version.study_id,
            "texts_version": version.version,
            "content_hash": version.content_hash,
            "created_at": version.created_at,
            **{key: version.texts.get(key, "") for key in TEXT_KEYS},
        }


def _assignment_rows(db: Session, study_id: int) -> Iterator[dict[str, Any]]:
    """How each arrival at the study's link was assigned (previews take none)."""
    query = select(Assignment).where(Assignment.study_id == study_id).order_by(Assignment.id)
    found = list(db.scalars(query))
    session_of = {a.id: a.session_id for a in found}
    for a in found:
        yield {
            "session_id": a.session_id,
            "condition": a.condition,
            "block": a.block,
            "position": a.position,
            "seed": a.seed,
            "refills_session_id": session_of.get(a.refills) if a.refills else None,
            "assigned_at": a.assigned_at,
        }


def _panel_rows(db: Session, study: Study, identified: bool) -> Iterator[dict[str, Any]]:
    """Each participant's panel ids: a keyed hash of the id (the study's secret link key is
    the key, so nobody can recompute it from a panel id alone) unless `identified`."""
    query = (
        select(PanelId, Participant.pseudonym)
        .join(Participant, Participant.id == PanelId.participant_id)
        .where(PanelId.study_id == study.id)
        .order_by(PanelId.id)
    )
    key = (study.join_key or "").encode()
    for row, pseudonym in db.execute(query):
        hashed = hmac.new(key, row.panel_id.encode(), hashlib.sha256).hexdigest()[:16]
        yield {
            "participant": pseudonym,
            "panel_id": row.panel_id if identified else hashed,
            "panel_params": json.dumps(row.params, sort_keys=True) if identified else None,
            "created_at": row.created_at,
        }


def export_study(
    db: Session,
    study_id: int,
    out: Path,
    fmt: str = "csv",
    panel_ids: bool = False,
) -> dict[str, int]:
    """Write the study's tables (`fmt`: csv or parquet), `datapackage.json`, `columns.csv`
    and `study.json` into `out`; returns the row count of each table file. The sessions'
    run columns are the fields of the run's declaration (`learner.run.declared`). `panel_ids`: the
    participants' panel ids as they are (for payment), not pseudonymous."""
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    study = get_study(db, study_id)
    out.mkdir(parents=True, exist_ok=True)
    query = select(StudySession).where(
        StudySession.study_id == study.id,
        StudySession.preview.is_(False),
        StudySession.pooled.is_(False),
    )
    sessions = list(db.scalars(query.order_by(StudySession.id)))
    q_of_session, q_of_task = _q_actions(db, sessions)
    columns = table_columns(q_of_task or None)
    rows = {
        "sessions": _session_rows(sessions, q_of_session),
        "texts_versions": _texts_rows(db, study.id),
        "episodes": _records(db, Episode, sessions, Episode.first_global_step),
        "steps": _records(db, Step, sessions, Step.global_step, q_of_session),
        "advice": _advice_rows(db, sessions, out),
        "feedback": _feedback_rows(db, sessions),
        "assignments": _assignment_rows(db, study.id),
        "panel_ids": _panel_rows(db, study, panel_ids),
        **visit_export.visit_rows(db, sessions),
    }
    write = write_parquet if fmt == "parquet" else write_csv
    counts, resources = {}, []
    for table in TABLES:
        name = f"{table}.{fmt}"
        counts[name] = write(out / name, columns[table], rows[table])
        resources.append(resource(table, name, columns[table], KEYS[table]))
    package = {
        "profile": "tabular-data-package",
        "name": f"ideeprl-study-{study.id}",
        "title": study.name,
        "description": study.description
        or "An IDeepRL study: sessions, their episodes, steps and advice.",
        "resources": resources,
    }
    (out / "datapackage.json").write_text(json.dumps(package, indent=2) + "\n")
    dictionary = [
        {"file": f"{table}.{fmt}", "column": c.name, "type": c.type, "unit": c.unit,
         "description": c.description}
        for table in TABLES
        for c in columns[table]
    ]  # fmt: skip
    write_csv(out / "columns.csv", DICTIONARY_COLUMNS, dictionary)
    (out / "study.json").write_text(
        json.dumps(
            {
                "id": study.id,
                "name": study.name,
                "description": study.description,
                "design": study.design,  # an online study's conditions, α, checks; else null
                "rows": counts,
            },
            indent=2,
        )
    )
    return counts


EXTRA_FILES = ("datapackage.json", "columns.csv", "study.json")
"""What an export writes besides its tables (and the `advice/` folder of images)."""


def clear_earlier_export(out: Path) -> int:
    """Remove what an earlier export wrote into `out` (its tables in either format, the
    data package, `advice/`), so a new one leaves nothing of the old study behind; returns
    the entries removed. A folder that holds anything else is refused, untouched."""
    ours = {*EXTRA_FILES, *(f"{t}.{fmt}" for t in TABLES for fmt in FORMATS)}
    entries = list(out.iterdir())
    foreign = sorted(
        e.name for e in entries if not ((e.name == "advice" and e.is_dir()) or e.name in ours)
    )
    if foreign:
        listed = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "")
        raise Conflict(f"{out} holds more than an earlier export ({listed}); choose another folder")
    for entry in entries:
        if entry.is_dir():
            shutil.rmtree(entry)
        else:
            entry.unlink()
    return len(entries)


def export_zip(
    db: Session, study_id: int, work_dir: Path, fmt: str = "csv", panel_ids: bool = False
) -> Path:
    """The study's export packed as one zip in a fresh temporary folder under `work_dir`."""
    work_dir.mkdir(parents=True, exist_ok=True)
    temp = Path(tempfile.mkdtemp(prefix=f"study-{study_id}-", dir=work_dir))
    folder = temp / f"study-{study_id}"
    try:
        export_study(db, study_id, folder, fmt, panel_ids=panel_ids)
        return Path(shutil.make_archive(str(folder), "zip", root_dir=folder))
    except BaseException:  # an unknown study, a full disk: no scratch folder left behind
        shutil.rmtree(temp, ignore_errors=True)
        raise
