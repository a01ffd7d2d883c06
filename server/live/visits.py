"""How an online study's visit ends: its outcome recorded once, and a visit that ended
early (declined, excluded, timed out) freed at once, so its worker's memory and its place
in the study go to the next arrival.

The first outcome wins: a participant who declines and then times out stays declined. A
completed visit leaves the learner training; the participant's code never waits on it.
"""

from __future__ import annotations

from typing import Protocol

from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from server.live.session import Changes
from study.db.models import Outcome, Status, StudySession, utcnow
from study.services.sessions import get_session


class SessionManager(Protocol):
    """What ending a visit needs of `server.live.manager.SessionManager` (which calls this
    module when a worker gives up waiting, so it is named here, not imported)."""

    factory: sessionmaker[Session]
    changes: Changes

    async def end(self, session_id: int, status: Status, detail: str) -> None: ...


DETAILS = {
    Outcome.declined: "the participant declined; their visit ended and its worker was stopped",
    Outcome.excluded: "the participant failed the comprehension check; their visit ended",
    Outcome.timed_out: "the participant gave no answer for the study's idle limit; their "
    "visit ended",
}


async def end_visit(manager: SessionManager, session_id: int, outcome: Outcome) -> None:
    """Record `outcome` for the session (unless one is recorded already); free a visit
    that ended early: worker stopped, status `declined`, `excluded` or `timed_out`."""
    assert outcome != Outcome.full, "an arrival turned away has no session"
    first = await run_in_threadpool(_record, manager, session_id, outcome)
    if first and outcome != Outcome.completed:
        await manager.end(session_id, Status(outcome.value), DETAILS[outcome])
    manager.changes.notify(session_id)


def _record(manager: SessionManager, session_id: int, outcome: Outcome) -> bool:
    """The outcome, written only where none is (atomic: two ends at once, one wins)."""
    with manager.factory() as db:
        result = db.execute(
            update(StudySession)
            .where(StudySession.id == session_id, StudySession.outcome.is_(None))
            .values(outcome=outcome.value, outcome_at=utcnow())
        )
        db.commit()
        return result.rowcount == 1  # type: ignore[attr-defined]


async def abandoned(manager: SessionManager, session_id: int) -> None:
    """A worker gave up waiting for its participant: in an online study that is the end
    of the visit (`timed_out`, final); a lab session stays `abandoned` (resumable)."""
    online = await run_in_threadpool(_online, manager, session_id)
    if online:
        await end_visit(manager, session_id, Outcome.timed_out)


def _online(manager: SessionManager, session_id: int) -> bool:
    with manager.factory() as db:
        return get_session(db, session_id).condition is not None
