"""A recorded episode as the dashboard's playback shows it: its logged steps (action, who
chose it, reward), the advice given during it (what the advisor saw, chose, and how long
a person took), and what its rerun needs (its session's run, reset seed, actions, rewards)."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.orm import Session

from study.db.models import Advice, Episode, Step, StudySession
from study.services.errors import Conflict, NotFound
from study.services.sessions import get_session


@dataclass(frozen=True)
class LoggedStep:
    global_step: int
    episode_step: int
    action: int
    action_source: str
    reward: float


@dataclass(frozen=True)
class AdviceTurn:
    advice_index: int
    global_step: int
    action: int
    advisor: str
    decision_time_s: float | None
    """Seconds the participant's page measured, from the buttons' activation to the
    choice (None for machine advisors and older records)."""
    response_time_s: float


@dataclass(frozen=True)
class RecordedEpisode:
    session: StudySession
    episode: Episode
    steps: list[LoggedStep]
    advice: list[AdviceTurn]


def recorded_episode(db: Session, session_id: int, stage: str, episode: int) -> RecordedEpisode:
    """The episode with its steps and advice; NotFound for an unknown session or episode,
    Conflict for one that cannot be rerun (no reset seed, or its steps are not all stored)."""
    session = get_session(db, session_id)
    found = db.scalar(
        select(Episode).where(
            Episode.session_id == session_id, Episode.stage == stage, Episode.episode == episode
        )
    )
    if found is None:
        raise NotFound(
            f"session {session_id} has no {stage} episode {episode}; "
            f"GET /api/sessions/{session_id}/episodes?stage=all lists them"
        )
    if found.reset_seed is None:
        raise Conflict(
            f"{stage} episode {episode} of session {session_id} was recorded before reset "
            "seeds were kept: it cannot be rerun"
        )
    span = (found.first_global_step, found.last_global_step)
    steps = [
        LoggedStep(s.global_step, s.episode_step, s.action, s.action_source, s.reward)
        for s in db.scalars(
            select(Step)
            .where(Step.session_id == session_id, Step.global_step.between(*span))
            .order_by(Step.global_step)
        )
    ]
    if len(steps) != found.steps:
        raise Conflict(
            f"{stage} episode {episode} of session {session_id} has {len(steps)} of its "
            f"{found.steps} steps stored: it cannot be rerun"
        )
    advice = [
        AdviceTurn(
            a.advice_index,
            a.global_step,
            a.action,
            a.advisor,
            a.decision_time_s,
            a.response_time_s,
        )
        for a in db.scalars(
            select(Advice)
            .where(Advice.session_id == session_id, Advice.global_step.between(*span))
            .order_by(Advice.advice_index)
        )
        if a.action is not None  # a replay's request past its recorded stream: none given
    ]
    return RecordedEpisode(session, found, steps, advice)
