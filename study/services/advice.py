"""Advice into the database: one typed message for every advisor, written once, complete.

A person's advice is built by the web process (`server/live/advising.py`) from the
worker's request (which carries the step and the learner's greedy action) and the
participant's answer, and written before it is forwarded (`store_advice`, a transaction of
its own), so it is durable as soon as the POST returns. A machine advisor's advice is built
by the worker (`runs/worker/advisors.py`, `RecordingAdvisor`) and written in the recorder's
batched flush (`write_advice`). No row is updated afterwards.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import insert, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from study.db.models import Advice


@dataclass(frozen=True)
class AdviceGiven:
    """One piece of advice, as its row in `advice` (docs/export.md, advice.csv)."""

    session_id: int
    advice_index: int
    """0-based index of this advice in the session."""
    global_step: int
    """The step it advised (from 1)."""
    advisor: str
    """`human`, or the machine advisor's method (agent, oracle, random, fitted, replayed)."""
    action: int | None
    """The advised action; None only for a replay's request beyond its recorded stream."""
    greedy_action: int
    """The learner's own greedy choice for the same observation."""
    observation_png: bytes
    """The image the advisor saw (PNG)."""
    response_time_s: float
    """Request to answer, server side (a person), or the advisor's compute time."""
    decision_time_s: float | None
    """The person's page's measured decision time, or a machine advisor's simulated one."""
    requested_at: datetime
    answered_at: datetime
    same_observation: bool | None = None
    """Replayed advice: whether it met the image its advisor saw; None otherwise."""
    correct_action: int | None = None
    """The task's correct action at the advised step (`tasks.Task.correct`); None where the
    task cannot say."""
    correct_actions: list[int] | None = None
    """Every action as right as the correct one there, the correct one among them
    (`tasks.Task.correct_actions`: the grid world's moves equally near the goal); None where
    the task cannot say."""


def write_advice(db: Session, advice: Sequence[AdviceGiven]) -> None:
    """Insert the advice rows (in the caller's transaction; the caller commits). A
    repeated (session, advice_index) raises `IntegrityError`: advice is written once."""
    if advice:
        db.execute(insert(Advice), [dataclasses.asdict(a) for a in advice])


def store_advice(factory: Callable[[], Session], advice: AdviceGiven) -> Advice | None:
    """Write one person's advice in a transaction of its own; None when written, or the row
    its (session, advice_index) has already (advice is written once: the first answer
    stands, and the caller answers with it)."""
    with factory() as db:
        try:
            db.execute(insert(Advice), [dataclasses.asdict(advice)])
            db.commit()
        except IntegrityError:
            db.rollback()
            stored = db.scalar(
                select(Advice).where(
                    Advice.session_id == advice.session_id,
                    Advice.advice_index == advice.advice_index,
                )
            )
            if stored is None:
                raise  # not a repeated advice: another integrity error
            return stored
    return None
