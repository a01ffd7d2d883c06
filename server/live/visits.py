"""How an online study's visit ends (`Outcome`).

PLACEHOLDER for the visit side's branch: the study side owns this module and replaces it
(codes, redirects, refilling places). Kept to the agreed signature so the check and the
questionnaire can end a visit now.
"""

from __future__ import annotations

import contextlib

from sqlalchemy import update
from starlette.concurrency import run_in_threadpool

from server.db.models import Outcome, Status, StudySession, utcnow
from server.live.manager import SessionManager
from server.services.errors import Conflict
from server.services.ownership import set_status


def _record(manager: SessionManager, session_id: int, outcome: Outcome) -> bool:
    """The outcome and its time, once: a visit that already ended keeps its outcome."""
    with manager.factory() as db:
        query = (
            update(StudySession)
            .where(StudySession.id == session_id, StudySession.outcome.is_(None))
            .values(outcome=outcome.value, outcome_at=utcnow())
        )
        changed = db.execute(query).rowcount == 1  # type: ignore[attr-defined]
        db.commit()
        return changed


async def end_visit(manager: SessionManager, session_id: int, outcome: Outcome) -> None:
    """End the participant's visit as `outcome`. A completed visit's learner trains on; any
    other outcome stops its worker at once and leaves the session stopped."""
    if not await run_in_threadpool(_record, manager, session_id, outcome):
        return
    if outcome == Outcome.completed:
        manager.notify(session_id)
        return
    with contextlib.suppress(Conflict):  # nothing ran: there is nothing to stop
        await manager.stop(session_id)
    with manager.factory() as db:
        set_status(db, session_id, Status.stopped, f"the participant's visit ended: {outcome}")
    manager.notify(session_id)
