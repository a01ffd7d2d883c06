"""A batch's runs in the database: find the session a run already has, create the missing
ones (taking back those whose worker died is `server.services.ownership.take_back`).

A run's identity is its study, method and `learning.identity` (seed, learner config,
sorting rule, strategy and its options, advisor, error rate, motion, scenario options),
compared as stored: the label is a name, not part of the identity, so a renamed batch still
finds its runs.
"""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from learner.run import RunSpec
from server.db.models import LIVE_STATUSES, RESUMABLE_STATUSES, Status, StudySession
from server.schemas.sessions import SessionCreate
from server.services import learning
from server.services.sessions import create_session

_RANK = {
    Status.finished.value: 0,
    **{s.value: 1 for s in LIVE_STATUSES},
    **{s.value: 2 for s in RESUMABLE_STATUSES},
    Status.created.value: 3,
}
"""Which of several matching sessions a run is: the furthest along (a failed one resumes
from its last checkpoint, like an interrupted one)."""


def find_session(db: Session, study_id: int, method: str, spec: RunSpec) -> StudySession | None:
    """The study's session for this run (`learning.identity`), the furthest along if
    several match; None if the run has none yet."""
    wanted = learning.identity(method, spec)
    query = select(StudySession).where(
        StudySession.study_id == study_id,
        StudySession.method == str(method),
        StudySession.seed == spec.seed,
    )
    matches = [
        s for s in db.scalars(query) if s.status in _RANK and learning.session_identity(s) == wanted
    ]
    if not matches:
        return None
    return min(matches, key=lambda s: (_RANK[s.status], s.id))


def ensure_session(
    db: Session, study_id: int, body: SessionCreate, spec: RunSpec
) -> tuple[StudySession, bool]:
    """The run's session (`spec`, what `body` describes), created if missing; True if
    created now."""
    found = find_session(db, study_id, body.method, spec)
    if found is not None:
        return found, False
    if body.advisor_checkpoint is not None:
        path = str(Path(body.advisor_checkpoint).resolve())
        body = body.model_copy(update={"advisor_checkpoint": path})
    return create_session(db, study_id, body, spec=spec), True
