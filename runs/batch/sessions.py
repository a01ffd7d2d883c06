"""A batch's runs in the database: find the session a run already has, create the missing
ones (taking back those whose worker died is `study.services.ownership.take_back`).

A run's identity is its study and `RunSpec.identity` (every field of the run in its stored
form, numerics only where the batch asked for them), compared with each stored run read
back by the same declaration (fields added since take their defaults): the label is a
name, not part of the identity, so a renamed batch still finds its runs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from learner.run import RunSpec
from study.db.models import LIVE_STATUSES, RESUMABLE_STATUSES, Status, StudySession
from study.schemas.sessions import SessionOptions
from study.services import replays
from study.services.sessions import create_session

_RANK = {
    Status.finished.value: 0,
    **{s.value: 1 for s in LIVE_STATUSES},
    **{s.value: 2 for s in RESUMABLE_STATUSES},
    Status.created.value: 3,
}
"""Which of several matching sessions a run is: the furthest along (a failed one resumes
from its last checkpoint, like an interrupted one)."""


def completed_sources(
    db: Session, study_id: int, methods: tuple[str, ...], feedback: str = "advice"
) -> list[int]:
    """The study's finished sessions of these methods whose feedback is `feedback` (advice
    or ratings, what the replayed runs are fed), by id: what `replayed` re-runs."""
    query = select(StudySession).where(
        StudySession.study_id == study_id, StudySession.status == Status.finished.value
    )
    return [
        s.id
        for s in db.scalars(query.order_by(StudySession.id))
        if s.method in methods and s.spec.normalized().feedback == feedback
    ]


def find_session(
    db: Session,
    study_id: int,
    spec: RunSpec,
    replay_of: int | None = None,
) -> StudySession | None:
    """The study's session for this run (`RunSpec.is_run`; a replay's, of `replay_of`),
    the furthest along if several match; None if the run has none yet."""
    wanted = spec.identity()
    query = select(StudySession).where(StudySession.study_id == study_id)
    matches = [
        s
        for s in db.scalars(query)
        if s.status in _RANK
        and s.method == spec.method
        and s.seed == spec.seed
        and s.replay_of == replay_of
        and _is_run(s, wanted)
    ]
    if not matches:
        return None
    return min(matches, key=lambda s: (_RANK[s.status], s.id))


def _is_run(session: StudySession, wanted: dict[str, Any]) -> bool:
    try:
        return session.spec.is_run(wanted)
    except (ValueError, TypeError):
        return False  # a run the learner can no longer read is never the same as a new one


def ensure_session(
    db: Session,
    study_id: int,
    spec: RunSpec,
    label: str,
    replay_of: int | None = None,
) -> tuple[StudySession, bool]:
    """The run's session, created (pinned on this machine) if missing; True if created now.
    A replay (`replay_of`: its source session) is fed the source's advice stream."""
    found = find_session(db, study_id, spec, replay_of)
    if found is not None:
        return found, False
    if replay_of is not None:
        stream = replays.stream_of_session(db, replay_of)
        return replays.create_replay(db, study_id, stream, spec, label), True
    if spec.advisor_checkpoint is not None:
        spec = spec.replace(advisor_checkpoint=str(Path(spec.advisor_checkpoint).resolve()))
    if spec.fitted_model is not None:
        spec = spec.replace(fitted_model=str(Path(spec.fitted_model).resolve()))
    return create_session(db, study_id, spec, SessionOptions(label=label)), True
