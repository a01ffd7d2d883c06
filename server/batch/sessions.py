"""A batch's runs in the database: find the session a run already has, create the missing
ones, and take back sessions whose worker died.

A run's identity is its study, method, seed and the configuration its session stores
(learner config, sorting rule, strategy, advisor, error rate, motion, scenario options),
compared as stored: the label is a name, not part of the identity, so a renamed batch still
finds its runs.
"""

from __future__ import annotations

import json
import socket
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from server.db.models import (
    LIVE_STATUSES,
    RESUMABLE_STATUSES,
    UNADVISED_METHODS,
    Status,
    StudySession,
)
from server.schemas.sessions import SessionCreate
from server.services import learning
from server.services.sessions import create_session, pid_alive, set_status

HOST = socket.gethostname()

_RANK = {
    Status.finished.value: 0,
    **{s.value: 1 for s in LIVE_STATUSES},
    **{s.value: 2 for s in RESUMABLE_STATUSES},
    Status.created.value: 3,
}
"""Which of several matching sessions a run is: the furthest along (a failed one resumes
from its last checkpoint, like an interrupted one)."""


def _plain(value: Any) -> Any:
    """As the database's JSON columns give it back."""
    return json.loads(json.dumps(value))


def _path(value: str | None) -> str | None:
    return None if value is None else str(Path(value).resolve())


def body_identity(body: SessionCreate) -> dict[str, Any]:
    """What a session created from `body` would store, in the fields that identify a run."""
    advised = body.method not in UNADVISED_METHODS
    config = learning.session_config(
        str(body.method),
        body.preset,
        body.config,
        episodes=body.episodes,
        max_episode_steps=body.max_episode_steps,
        advice_budget=body.advice_budget if advised else 0,
    )
    return {
        "method": str(body.method),
        "seed": body.seed,
        "config": _plain(config),
        "sort_rule": _plain(learning.parse_sort_rule(body.sort_rule)),
        "strategy": body.strategy if advised else None,
        "advisor_checkpoint": _path(body.advisor_checkpoint),
        "oracle_error_rate": body.oracle_error_rate if body.method == "oracle" else None,
        "motion": body.motion or "fast",
        "scenario": learning.parse_scenario(body.scenario.model_dump()),
    }


def _stored_config(config: dict[str, Any]) -> dict[str, Any]:
    """A stored learner config as the learner reads it back: fields added to the learner
    since it was stored take their defaults (as when a checkpoint is resumed); an sb3-dqn
    session's `sb3_*` fields are compared as stored."""
    from learner import DQNConfig
    from learner.sb3_dqn import split_config

    learner, sb3 = split_config(config)
    try:
        return _plain({**DQNConfig.from_dict(learner).to_dict(), **sb3})
    except (ValueError, TypeError):  # a field the learner no longer has: never the same run
        return _plain(config)


def _stored_scenario(scenario: dict[str, Any] | None) -> dict[str, Any]:
    """Stored scenario options with the defaults filled in (a session stored before they
    existed ran the paper's scenario)."""
    try:
        return learning.parse_scenario(scenario)
    except ValueError:  # an option the scenario no longer has: never the same run
        return _plain(scenario)


def session_identity(session: StudySession) -> dict[str, Any]:
    return {
        "method": session.method,
        "seed": session.seed,
        "config": _stored_config(session.config),
        "sort_rule": _plain(session.sort_rule),
        "strategy": session.strategy,
        "advisor_checkpoint": _path(session.advisor_checkpoint),
        "oracle_error_rate": session.oracle_error_rate,
        "motion": session.motion,
        "scenario": _stored_scenario(session.scenario),
    }


def find_session(db: Session, study_id: int, body: SessionCreate) -> StudySession | None:
    """The study's session for this run, the furthest along if several match; None if the
    run has none yet."""
    wanted = body_identity(body)
    query = select(StudySession).where(
        StudySession.study_id == study_id,
        StudySession.method == str(body.method),
        StudySession.seed == body.seed,
    )
    matches = [s for s in db.scalars(query) if s.status in _RANK and session_identity(s) == wanted]
    if not matches:
        return None
    return min(matches, key=lambda s: (_RANK[s.status], s.id))


def ensure_session(db: Session, study_id: int, body: SessionCreate) -> tuple[StudySession, bool]:
    """The run's session, created if missing; True if created now."""
    found = find_session(db, study_id, body)
    if found is not None:
        return found, False
    if body.advisor_checkpoint is not None:
        body = body.model_copy(update={"advisor_checkpoint": _path(body.advisor_checkpoint)})
    return create_session(db, study_id, body), True


def worker_gone(session: StudySession, stale_after_s: float) -> bool:
    """A running or paused session whose worker cannot be alive: its process is gone on
    this host, or it has not written for `stale_after_s` (a worker on another host)."""
    if session.worker_host == HOST and session.worker_pid is not None:
        return not pid_alive(session.worker_pid)
    heartbeat = session.heartbeat_at
    if heartbeat is None:
        return True
    if heartbeat.tzinfo is None:
        heartbeat = heartbeat.replace(tzinfo=UTC)
    return heartbeat < datetime.now(UTC) - timedelta(seconds=stale_after_s)


def take_back(db: Session, session_ids: list[int], stale_after_s: float) -> list[int]:
    """Mark this batch's sessions whose worker died `interrupted`, so they can resume.

    Only the given sessions: a paused human session of the study server is none of ours."""
    if not session_ids:
        return []
    query = select(StudySession).where(
        StudySession.id.in_(session_ids),
        StudySession.status.in_([s.value for s in LIVE_STATUSES]),
    )
    marked = []
    for session in list(db.scalars(query)):
        if worker_gone(session, stale_after_s) and set_status(
            db,
            session.id,
            Status.interrupted,
            "its batch worker stopped without finishing; the batch resumes it",
            token=session.worker_token,
        ):
            marked.append(session.id)
    return marked
