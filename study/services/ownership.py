"""Who owns a running session: the claim, the writes only its owner may make, and the one
rule that says its worker is gone.

Every process that runs sessions goes through here: the web process (its manager claims,
and takes back the sessions of dead workers), the worker (its final status), and the batch
runner (its runs, and the runs of a batch whose worker died). A session row's
`worker_token` is the lease; `worker_host`, `worker_pid` and `heartbeat_at` say whether its
holder can still be alive.
"""

from __future__ import annotations

import os
import socket
import uuid
from collections.abc import Iterable
from datetime import UTC, datetime, timedelta

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from study.db.models import (
    ENDED_EARLY,
    LIVE_STATUSES,
    RESUMABLE_STATUSES,
    Status,
    StudySession,
    utcnow,
)
from study.services.errors import Conflict, NotFound

HOST = socket.gethostname()
"""This machine, as a session row names the host of its worker."""
LIVE = [s.value for s in LIVE_STATUSES]


def claim(db: Session, session_id: int, resume: bool) -> str:
    """Mark the session running under a new worker token, or say why it cannot run.

    The conditional UPDATE makes the claim atomic: two starts of one session (two clicks,
    a server and a batch runner) cannot both get it."""
    session = db.get(StudySession, session_id)
    if session is None:
        raise NotFound(f"no session with id {session_id}; GET /api/studies/ID/sessions lists them")
    allowed = [Status.created] if not resume else list(RESUMABLE_STATUSES)
    if session.status not in [s.value for s in allowed]:
        if session.status in LIVE:
            raise Conflict(f"session {session_id} is {session.status} already")
        if session.status == Status.finished:
            raise Conflict(f"session {session_id} has finished; create a new session to rerun it")
        if session.status in [s.value for s in ENDED_EARLY]:
            raise Conflict(
                f"session {session_id} is {session.status}: its participant's visit has ended "
                "and it cannot run again; the study's link gives the place to a new arrival"
            )
        if not resume:
            raise Conflict(f"session {session_id} is {session.status}; resume it instead of start")
        raise Conflict(f"session {session_id} is {session.status} and cannot be resumed")
    token = uuid.uuid4().hex
    now = utcnow()
    result = db.execute(
        update(StudySession)
        .where(StudySession.id == session_id, StudySession.status == session.status)
        .values(
            status=Status.running.value,
            status_detail="",
            worker_token=token,
            worker_host=HOST,
            worker_pid=None,
            heartbeat_at=now,
            started_at=session.started_at or now,
        )
    )
    db.commit()
    if result.rowcount != 1:  # type: ignore[attr-defined]
        raise Conflict(f"session {session_id} was started by someone else just now")
    return token


def set_status(
    db: Session, session_id: int, status: Status, detail: str = "", token: str | None = None
) -> bool:
    """Set the status, only if `token` (when given) still owns the session."""
    query = update(StudySession).where(StudySession.id == session_id)
    if token is not None:
        query = query.where(StudySession.worker_token == token)
    values: dict[str, object] = {"status": status.value, "status_detail": detail}
    if status not in LIVE_STATUSES:
        values["worker_pid"] = None  # no process runs it now (its worker writes this last)
    if status == Status.finished:
        values["finished_at"] = utcnow()
    result = db.execute(query.values(**values))
    db.commit()
    return result.rowcount == 1  # type: ignore[attr-defined]


def pid_alive(pid: int) -> bool:
    """Whether a process of this id runs on this host (one we may not signal counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def silent(session: StudySession, stale_after_s: float) -> bool:
    """Its worker has not marked itself alive for `stale_after_s` (hung, or gone)."""
    heartbeat = session.heartbeat_at
    if heartbeat is None:
        return True
    if heartbeat.tzinfo is None:
        heartbeat = heartbeat.replace(tzinfo=UTC)
    return heartbeat < datetime.now(UTC) - timedelta(seconds=stale_after_s)


def worker_gone(session: StudySession, stale_after_s: float) -> bool:
    """The one rule: a live session's worker is gone when its process is dead on this host,
    or it has been silent for `stale_after_s` (a worker on another host, or a hung one)."""
    dead_here = (
        session.worker_host == HOST
        and session.worker_pid is not None
        and not pid_alive(session.worker_pid)
    )
    return dead_here or silent(session, stale_after_s)


def _live(db: Session, ids: Iterable[int] | None = None) -> list[StudySession]:
    query = select(StudySession).where(StudySession.status.in_(LIVE))
    if ids is not None:
        query = query.where(StudySession.id.in_(list(ids)))
    return list(db.scalars(query))


def mark_dead_interrupted(db: Session, stale_after_s: float, owned: set[int]) -> list[int]:
    """Sessions marked running/paused whose worker is gone become `interrupted` (resumable).

    Sessions whose worker this process owns are the manager's to judge (`silent_sessions`):
    it kills a hung worker before marking its session."""
    marked = []
    for session in _live(db):
        if session.id not in owned and worker_gone(session, stale_after_s):
            session.status = Status.interrupted.value
            session.status_detail = "its worker stopped without finishing; resume it"
            session.worker_pid = None
            marked.append(session.id)
    db.commit()
    return marked


def silent_sessions(db: Session, stale_after_s: float, ids: set[int]) -> list[tuple[int, str]]:
    """(id, worker token) of the live sessions among `ids` whose worker has not marked
    itself alive for `stale_after_s`: hung (stopped, deadlocked, swapped out for good)."""
    if not ids:
        return []
    return [
        (s.id, s.worker_token)
        for s in _live(db, ids)
        if silent(s, stale_after_s) and s.worker_token
    ]


def take_back(db: Session, session_ids: list[int], stale_after_s: float) -> list[int]:
    """Mark these sessions `interrupted` where their worker is gone, so they can resume
    (the batch's own runs only: a paused human session of the study server is not its)."""
    if not session_ids:
        return []
    marked = []
    for session in _live(db, session_ids):
        if worker_gone(session, stale_after_s) and set_status(
            db,
            session.id,
            Status.interrupted,
            "its batch worker stopped without finishing; the batch resumes it",
            token=session.worker_token,
        ):
            marked.append(session.id)
    return marked
