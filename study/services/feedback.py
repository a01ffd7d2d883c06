"""Evaluative feedback into the database: one typed message for every evaluator, written
once, complete (as `study.services.advice` writes advice).

A machine evaluator's judgements are built by the worker (`runs/worker/advisors.py`,
`RecordingEvaluator`) and written in the recorder's batched flush; no row is updated
afterwards.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import func, insert, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from study.db.models import Feedback


@dataclass(frozen=True)
class FeedbackGiven:
    """One judgement, as its row in `feedback` (docs/export.md, feedback.csv)."""

    session_id: int
    feedback_index: int
    """0-based index of this judgement in the session."""
    global_step: int
    """The step whose action it judged (from 1)."""
    evaluator: str
    """The machine evaluator's method (oracle, agent)."""
    action: int
    """The action judged: the learner's own, the one taken."""
    judgement: float | None
    """+1 good, -1 bad; None: no answer."""
    shaping: float
    """What it added to the environment's reward in the learner's memory."""
    greedy_action: int
    observation_hash: str
    """The image the learner chose the action on (`learner.records.observation_hash`)."""
    response_time_s: float
    decision_time_s: float | None
    requested_at: datetime
    answered_at: datetime
    correct_action: int | None = None
    """The task's correct action at the rated step (`tasks.Task.correct`), for the rating's
    accuracy; None where the task cannot say."""
    correct_actions: list[int] | None = None
    """Every action as right as the correct one there, the correct one among them
    (`tasks.Task.correct_actions`); None where the task cannot say."""


def write_feedback(db: Session, feedback: Sequence[FeedbackGiven]) -> None:
    """Insert the judgements (in the caller's transaction; the caller commits). A repeated
    (session, feedback_index) raises `IntegrityError`: a judgement is written once."""
    if feedback:
        db.execute(insert(Feedback), [dataclasses.asdict(f) for f in feedback])


def store_feedback(factory: Callable[[], Session], given: FeedbackGiven) -> bool:
    """Write one person's judgement in a transaction of its own; False when its (session,
    feedback_index) is stored already (a judgement is written once: the first stands)."""
    with factory() as db:
        try:
            db.execute(insert(Feedback), [dataclasses.asdict(given)])
            db.commit()
        except IntegrityError:
            db.rollback()
            return False
    return True


PERSON = "human"
"""The evaluator of a participant's ratings (the advice page's Good and Bad)."""


def rated_turns(db: Session, session_id: int) -> list[Feedback]:
    """The participant's rated turns so far, answered or lapsed, in order."""
    query = (
        select(Feedback)
        .where(Feedback.session_id == session_id, Feedback.evaluator == PERSON)
        .order_by(Feedback.feedback_index)
    )
    return list(db.scalars(query))


def judgements_given(db: Session, session_id: int) -> int:
    """How many of the session's turns were judged (answered or not): a rating session's
    count of turns, as its advice rows are an advice session's."""
    query = select(func.count()).where(Feedback.session_id == session_id)
    return db.scalar(query) or 0
