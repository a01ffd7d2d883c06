"""What a study and its sessions keep on disk (checkpoints, reports, export scratch), how
much, and deletion that removes it all with the rows.

Deleting is how a participant's data goes: their session's rows (steps, episodes, advice
with the images they saw), its checkpoints, the study's report (built from their data),
the advisor models fitted from their advice (`fitted_advisors`, and their files), the
replays made from their advice (`sessions.replay_of`) and the `fitted` runs those models
advised (each in any study, with their files and their studies' reports), and their
pseudonym once no session of theirs remains. Rows go
first, in one transaction; files after, so a failure leaves files of a deleted session
(removed again when the id would be used, which it never is: ids are not reused), never
rows without their files.

Reports, exports and fitted models lie in the data folder (`data_dir`); checkpoints under
the checkpoint root (`checkpoints`), which is the data folder too unless a Ray cluster's
nodes share a storage root apart from it (`Settings.checkpoint_root`), where a row's
relative checkpoint path starts.
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session

from study.db.models import (
    LIVE_STATUSES,
    FittedAdvisorModel,
    Participant,
    Status,
    Study,
    StudySession,
    located,
)
from study.services.errors import Conflict, NotFound
from study.services.fitted_files import fitted_model_path
from study.services.replays import replays_of
from study.services.studies import get_study

log = logging.getLogger(__name__)
LIVE = [s.value for s in LIVE_STATUSES]


def session_dir(checkpoints: Path, session_id: int) -> Path:
    """A session's checkpoint folder under the checkpoint root (the worker's
    `data_dir/checkpoints/session-ID`)."""
    return checkpoints / "checkpoints" / f"session-{session_id}"


def _report_paths(data_dir: Path, study_id: int) -> list[Path]:
    reports = data_dir / "reports"
    found = [reports / f"study-{study_id}", reports / f"study-{study_id}.json"]
    found += reports.glob(f".study-{study_id}-*") if reports.is_dir() else []
    found += reports.glob(f".old-study-{study_id}-*") if reports.is_dir() else []
    scratch = data_dir / "exports" / "tmp"
    found += scratch.glob(f"study-{study_id}-*") if scratch.is_dir() else []
    return found


def _remove(path: Path) -> None:
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)
    except OSError as error:
        log.error("could not remove %s: %s", path, error)


def _inside(path: Path, folder: Path) -> bool:
    try:
        return path.resolve().is_relative_to(folder.resolve())
    except OSError:
        return False


def remove_session_files(checkpoints: Path, session_id: int, checkpoint: str | None) -> None:
    """A session's checkpoint folder and its stored checkpoint, under the checkpoint root."""
    _remove(session_dir(checkpoints, session_id))
    file = located(checkpoint, checkpoints)
    if file is not None and _inside(file, checkpoints):
        _remove(file)


def remove_study_files(data_dir: Path, study_id: int) -> None:
    for path in _report_paths(data_dir, study_id):
        _remove(path)


def _made_from(
    db: Session,
    data_dir: Path,
    session_ids: set[int],
    models: list[FittedAdvisorModel] | None = None,
) -> tuple[list[StudySession], list[FittedAdvisorModel]]:
    """What was made from these sessions' data (and from `models`), in any study: their
    replays, the advisor models fitted from their advice, the `fitted` runs those models
    advised (a run names its model's file), and in turn what was made from those. A
    participant's data lives on in each of them."""
    every_model = list(db.scalars(select(FittedAdvisorModel)))
    fitted_runs = [s for s in db.scalars(select(StudySession)) if s.method == "fitted"]
    known = set(session_ids)
    made: list[StudySession] = []
    used: dict[int, FittedAdvisorModel] = {}
    frontier, fresh = set(session_ids), list(models or [])
    while frontier or fresh:
        replays = [r for r in replays_of(db, frontier) if r.id not in known]
        reached = frontier | {r.id for r in replays}
        fresh += [
            m for m in every_model if m.id not in used and reached & {int(i) for i in m.session_ids}
        ]
        used.update((m.id, m) for m in fresh)
        files = {str(fitted_model_path(data_dir, m.study_id, m.id).resolve()) for m in fresh}
        known.update(r.id for r in replays)
        runs = [s for s in fitted_runs if s.id not in known and _model_file(s) in files]
        known.update(s.id for s in runs)
        made += [*replays, *runs]
        frontier, fresh = {s.id for s in runs}, []
    return made, list(used.values())


def _model_file(session: StudySession) -> str | None:
    """The model file a `fitted` run names, resolved as the model's own path is."""
    name = session.run.get("fitted_model")
    return str(Path(name).resolve()) if isinstance(name, str) and name else None


def remove_fitted_files(data_dir: Path, models: list[tuple[int, int]]) -> None:
    for study_id, model_id in models:
        _remove(fitted_model_path(data_dir, study_id, model_id))


def _refuse_live(session: StudySession, live_here: bool) -> None:
    if session.status in LIVE or live_here:
        raise Conflict(
            f"session {session.id} is {session.status}; stop it first "
            f"(POST /api/sessions/{session.id}/stop)"
        )


def _file(path: str | None, checkpoints: Path) -> Path | None:
    """The file a stored path names (relative: under the checkpoint root), resolved."""
    found = located(path, checkpoints)
    return found.resolve() if found is not None else None


def _advised_by(db: Session, sessions: list[StudySession], checkpoints: Path) -> list[int]:
    """Unfinished sessions elsewhere whose advisor is one of these sessions' checkpoints
    (each path stored relative to the checkpoint root or absolute, as the database was
    written)."""
    files = {_file(s.checkpoint_path, checkpoints) for s in sessions if s.checkpoint_path}
    if not files:
        return []
    ids = {s.id for s in sessions}
    query = select(StudySession).where(StudySession.status != Status.finished.value)
    return [
        s.id
        for s in db.scalars(query)
        if s.id not in ids and _file(s.run.get("advisor_checkpoint"), checkpoints) in files
    ]


def delete_session(
    db: Session,
    data_dir: Path,
    session_id: int,
    live_here: bool,
    checkpoints: Path | None = None,
) -> None:
    """Delete one session: rows, checkpoints, the study's report, and what was made from its
    data (`_made_from`); refused while any of them runs. `checkpoints`: the checkpoint root
    (None: the data folder)."""
    checkpoints = checkpoints or data_dir
    session = db.get(StudySession, session_id)
    if session is None:
        raise NotFound(f"no session with id {session_id}")
    _refuse_live(session, live_here)
    made, models = _made_from(db, data_dir, {session_id})
    for other in made:
        _refuse_live(other, False)
    advised = _advised_by(db, [session, *made], checkpoints)
    if advised:
        raise Conflict(
            f"session {session_id}'s checkpoint advises unfinished session(s) "
            f"{', '.join(map(str, advised))}; delete or finish them first"
        )
    study_id, checkpoint, participant_id = session.study_id, session.checkpoint_path, None
    derived = [(r.id, r.checkpoint_path, r.study_id) for r in made]
    if session.participant_id is not None:
        others = db.scalar(
            select(func.count()).where(
                StudySession.participant_id == session.participant_id,
                StudySession.id != session_id,
            )
        )
        participant_id = None if others else session.participant_id
    fitted = [(m.study_id, m.id) for m in models]
    db.execute(delete(FittedAdvisorModel).where(FittedAdvisorModel.id.in_([m.id for m in models])))
    # The database deletes the replays with their sources (replay_of cascades).
    db.execute(delete(StudySession).where(StudySession.id.in_([r.id for r in made])))
    db.delete(session)
    if participant_id is not None:
        participant = db.get(Participant, participant_id)
        if participant is not None:
            db.delete(participant)
    db.commit()
    remove_session_files(checkpoints, session_id, checkpoint)
    remove_fitted_files(data_dir, fitted)
    remove_study_files(data_dir, study_id)  # its report was built from this session's data
    for made_id, made_checkpoint, made_study in derived:
        remove_session_files(checkpoints, made_id, made_checkpoint)
        remove_study_files(data_dir, made_study)


def delete_study(
    db: Session, data_dir: Path, study_id: int, live: set[int], checkpoints: Path | None = None
) -> None:
    """Delete a study with its sessions, participants, checkpoints, report and exports, its
    fitted models, and what was made from its sessions' data and models elsewhere.
    `checkpoints`: the checkpoint root (None: the data folder)."""
    checkpoints = checkpoints or data_dir
    study = get_study(db, study_id)
    sessions = list(study.sessions)
    running = [s.id for s in sessions if s.status in LIVE or s.id in live]
    if running:
        raise Conflict(
            f"study {study_id} has {len(running)} running session(s) "
            f"({', '.join(map(str, running))}); stop them first"
        )
    own_models = list(
        db.scalars(select(FittedAdvisorModel).where(FittedAdvisorModel.study_id == study_id))
    )
    made, models = _made_from(db, data_dir, {s.id for s in sessions}, own_models)
    elsewhere = [r for r in made if r.study_id != study_id]
    running += [r.id for r in elsewhere if r.status in LIVE or r.id in live]
    if running:
        raise Conflict(
            f"study {study_id}'s sessions have running replay(s) or fitted run(s) in other "
            f"studies ({', '.join(map(str, running))}); stop them first"
        )
    advised = _advised_by(db, [*sessions, *made], checkpoints)
    if advised:
        raise Conflict(
            f"study {study_id}'s sessions advise unfinished session(s) "
            f"{', '.join(map(str, advised))} of other studies; delete or finish them first"
        )
    files = [(s.id, s.checkpoint_path) for s in [*sessions, *made]]
    fitted = [(m.study_id, m.id) for m in models]
    # Core deletes: the database deletes each study's sessions, and their replays anywhere
    # (foreign keys cascade), where the ORM would delete a replay of this study twice.
    db.execute(delete(FittedAdvisorModel).where(FittedAdvisorModel.id.in_([m.id for m in models])))
    db.execute(delete(StudySession).where(StudySession.id.in_([r.id for r in elsewhere])))
    db.execute(delete(Study).where(Study.id == study_id))
    db.commit()
    remove_fitted_files(data_dir, fitted)
    for session_id, checkpoint in files:
        remove_session_files(checkpoints, session_id, checkpoint)
    for other in {study_id, *(r.study_id for r in elsewhere)}:
        remove_study_files(data_dir, other)


def _size(path: Path) -> int:
    try:
        if path.is_file():
            return path.stat().st_size
        if path.is_dir():
            return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    except OSError:
        pass
    return 0


@dataclass(frozen=True)
class DiskUse:
    """What a study keeps on disk beside its rows, in bytes."""

    study_id: int
    session_bytes: dict[int, int]
    """Each session's folder (and its checkpoint kept elsewhere), by session id, in order."""
    report_bytes: int
    """Its report and any export being packed."""


def study_disk(
    db: Session, data_dir: Path, study_id: int, checkpoints: Path | None = None
) -> DiskUse:
    """`checkpoints`: the checkpoint root (None: the data folder)."""
    checkpoints = checkpoints or data_dir
    study = get_study(db, study_id)
    found = {}
    for session in sorted(study.sessions, key=lambda s: s.id):
        folder = session_dir(checkpoints, session.id)
        size = _size(folder)
        checkpoint = located(session.checkpoint_path, checkpoints)
        if checkpoint is not None and not _inside(checkpoint, folder):
            size += _size(checkpoint)
        found[session.id] = size
    reports = sum(_size(p) for p in _report_paths(data_dir, study_id))
    return DiskUse(study_id, found, reports)
