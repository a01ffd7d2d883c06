"""Which interrupted sessions a server's start resumes by itself (`resumes_after_restart`):
a person's session that this version's shutdown in order interrupted, while the person
could still be there. The restart itself, on a live server: tests/server/test_resume.py."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from runs.worker.link import SHUT_DOWN_WHILE_PAUSED, SHUTTING_DOWN
from server.live.manager import RESUME_WITHIN_S, resumes_after_restart
from study.db.models import Status, StudySession

NOW = datetime(2026, 12, 5, 12, 0, tzinfo=UTC)


def interrupted(
    method: str = "human",
    detail: str = SHUTTING_DOWN,
    quiet_s: float = 5.0,
    idle_limit_s: float | None = None,
    pooled: bool = False,
) -> StudySession:
    return StudySession(
        run={"method": method},
        status=Status.interrupted,
        status_detail=detail,
        heartbeat_at=NOW - timedelta(seconds=quiet_s),
        idle_limit_s=idle_limit_s,
        pooled=pooled,
    )


def test_a_persons_session_a_restart_interrupted_a_moment_ago_resumes() -> None:
    assert resumes_after_restart(interrupted(), NOW)
    assert resumes_after_restart(interrupted(detail=f"{SHUTTING_DOWN} as it started training"), NOW)
    assert resumes_after_restart(interrupted(quiet_s=500, idle_limit_s=600), NOW)


@pytest.mark.parametrize(
    "session",
    [
        interrupted(method="oracle"),  # a machine's: for its batch or researcher
        interrupted(pooled=True),  # its pool makes it again
        interrupted(detail=SHUT_DOWN_WHILE_PAUSED),  # the researcher paused it
        interrupted(detail="the worker stopped: exit code -9"),  # a crash
        interrupted(detail="the server is shutting down"),  # an older version's shutdown
        interrupted(quiet_s=700, idle_limit_s=600),  # its person's idle limit has passed
        interrupted(quiet_s=RESUME_WITHIN_S + 60),  # a lab session left long ago
    ],
    ids=["machine", "pooled", "paused", "crashed", "older-version", "online-gone", "lab-gone"],
)
def test_the_others_stay_for_the_researcher(session: StudySession) -> None:
    assert not resumes_after_restart(session, NOW)
