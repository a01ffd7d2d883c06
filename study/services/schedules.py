"""An advised session's advising procedure as a `learner.procedure.Schedule`, read from its
steps, for the procedure control that follows it (the batch's `procedure` method)."""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from learner.procedure import Schedule
from study.db.models import Feedback, Step, StudySession


def schedule_of(db: Session, session: StudySession) -> Schedule:
    """The session's schedule: its advised steps (a judged session's: the steps judged, an
    answer given), its pretraining fits, its epsilon path."""
    rows = db.execute(
        select(Step.global_step, Step.stage, Step.action_source, Step.loss, Step.epsilon)
        .where(Step.session_id == session.id)
        .order_by(Step.global_step)
    ).tuples()
    judged = db.scalars(
        select(Feedback.global_step).where(
            Feedback.session_id == session.id, Feedback.judgement.is_not(None)
        )
    )
    spec = session.spec
    return Schedule.from_steps(rows, spec.config.pretraining_steps, f"session {session.id}", judged)


def write_schedule(db: Session, session: StudySession, directory: Path) -> Path:
    """The session's schedule as a file in `directory` (written once: a finished session's
    steps do not change), its absolute path."""
    path = (directory / f"session-{session.id}.json").resolve()
    if not path.is_file():
        schedule_of(db, session).save(path)
    return path
