"""The participant's side of a human session: what their page shows, and their advice.

An advice is written to the database, complete (the worker's request carries its step and
the learner's greedy action: `study.services.advice`), before it is forwarded to the worker,
so nothing a participant gave is lost if the tab closes or the worker dies; a resumed worker
replays it. Submitting the same advice twice is acknowledged but stored once.
"""

from __future__ import annotations

import base64
import time
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import func, select
from starlette.concurrency import run_in_threadpool

from runs.worker.messages import AdviceAnswer, AdviceRequest
from server.live import rating
from server.live.manager import SessionManager
from server.live.session import HistoryEntry
from server.live.trainers import QUEUED, shown_status
from study.db.models import Advice, Status, StudySession
from study.schemas.participant import (
    AdviceCreate,
    AdviceReceipt,
    HeldObject,
    HistoryItem,
    ParticipantState,
)
from study.services.advice import AdviceGiven, store_advice
from study.services.consent import NOT_CONSENTED
from study.services.errors import Conflict, Invalid, NotFound
from study.services.feedback import judgements_given
from tasks import get_task


@dataclass(frozen=True)
class ParticipantSession:
    """The one session a participant token reaches (what the participant routes need)."""

    id: int
    advice_budget: int
    condition: str | None = None
    """The online study's condition (None: a lab session)."""
    task: str = "sorting"
    """The run's task (`tasks`): its actions' words, and how many there are."""

    @property
    def action_words(self) -> tuple[str, ...]:
        return get_task(self.task).action_words


MESSAGES = {
    QUEUED: "Your turns are done. The rest of the practice waits in line for its turn; you "
    "may close this page.",
    Status.created: "The session has not started yet.",
    Status.paused: "The session is paused by the researcher; please wait.",
    Status.finished: "The session has finished. Thank you!",
    Status.stopped: "The session was stopped by the researcher.",
    Status.interrupted: "The session was interrupted; the researcher can resume it.",
    Status.abandoned: "The session waited too long for advice; the researcher can resume it.",
    Status.failed: "The session failed; please tell the researcher.",
    Status.declined: "You declined to take part; your visit has ended.",
    Status.excluded: "Your visit has ended; reload the page for your code.",
    Status.timed_out: "The study waited too long for you and has ended; reload the page for "
    "your code.",
}


def _history(entries: list[HistoryEntry], words: tuple[str, ...]) -> list[HistoryItem]:
    return [
        HistoryItem(
            advice_index=e.advice_index,
            action=e.action,
            action_name=words[e.action],
            reward=e.reward,
        )
        for e in entries
    ]


def _arm(info: dict[str, Any]) -> dict[str, Any]:
    """What the robot holds and where, from the request's ground truth, for the page's words."""
    held = info.get("held")  # "" or "shape/color" (sim's info, docs/architecture.md)
    return {
        "held": HeldObject(shape=info["held_shape"], color=info["held_color"]) if held else None,
        "station": info.get("station"),
    }


def _own_moves(request: AdviceRequest | None, history: Iterable[HistoryEntry]) -> int | None:
    """The robot's own moves between the last advised step and this request's (the
    `alternating` strategy's turns come after some; None before the first choice)."""
    if request is None:
        return None
    before = [e.global_step for e in history if e.advice_index < request.advice_index]
    return request.global_step - max(before) - 1 if before else None


async def current_state(manager: SessionManager, session: ParticipantSession) -> ParticipantState:
    """`participant_state` from an async route: a session without a live worker is read
    from the database in a worker thread, so a crowd polling finished or queued sessions
    never blocks the event loop (a live one is answered from memory, on the loop)."""
    if manager.live(session.id) is None:
        return await run_in_threadpool(participant_state, manager, session)
    return participant_state(manager, session)


def participant_state(manager: SessionManager, session: ParticipantSession) -> ParticipantState:
    """The page's state; showing a pending request starts its response-time clock."""
    version = manager.changes.version(session.id)
    live = manager.live(session.id)
    budget = session.advice_budget
    if live is None:
        with manager.factory() as db:
            given = db.scalar(select(func.count()).where(Advice.session_id == session.id)) or 0
            given += judgements_given(db, session.id)  # a rating session's turns
            row = db.get(StudySession, session.id)
            if row is None:
                raise NotFound("this session no longer exists")
            stored, progress = row.status, row.progress
            ready = row.ready_for_advice
        status, place = shown_status(manager.trainers, session.id, stored)
        return ParticipantState(
            session_id=session.id,
            status=status,
            message=MESSAGES.get(status, ""),
            version=version,
            advice_wanted=False,
            robot_moving=False,
            advice_budget=budget,
            advice_given=given,
            advice_left=max(0, budget - given),
            episode=int(progress.get("episode", 0)),
            stage=progress.get("stage"),
            ready=ready,
            queued=status == QUEUED,
            queue_place=place,
            action_names=list(session.action_words),
        )
    request = live.show()
    wanted = request is not None and live.status == Status.running
    shown = live.progress
    given = len(live.given)
    status, place = shown_status(manager.trainers, session.id, live.status)
    state = ParticipantState(
        session_id=session.id,
        status=status,
        message=MESSAGES.get(status, ""),
        version=version,
        advice_wanted=wanted,
        advice_index=request.advice_index if request is not None else None,
        observation_png=(
            base64.b64encode(request.observation_png).decode() if request is not None else None
        ),
        robot_moving=live.moving,
        **_arm(request.info if request is not None else {}),
        advice_budget=budget,
        advice_given=given,
        advice_left=max(0, budget - given),
        own_moves=_own_moves(request, live.history),
        last_reward=live.last_reward,
        episode=shown.episode if shown else 0,
        stage=shown.stage if shown else None,
        ready=live.ready,
        queued=status == QUEUED,
        queue_place=place,
        history=_history(list(live.history), session.action_words),
        action_names=list(session.action_words),
        frame_png=(
            base64.b64encode(request.frame_png).decode()
            if request is not None and request.frame_png is not None
            else None
        ),
    )
    rating.shown(state, request, live.request_arrived)
    return state


def observation_png(manager: SessionManager, session: ParticipantSession) -> bytes | None:
    """The image of the pending request, or of the latest advice given."""
    live = manager.live(session.id)
    if live is not None and live.request is not None:
        return live.request.observation_png
    with manager.factory() as db:
        return db.scalar(
            select(Advice.observation_png)
            .where(Advice.session_id == session.id)
            .order_by(Advice.advice_index.desc())
            .limit(1)
        )


def _ready(manager: SessionManager, session_id: int) -> bool:
    with manager.factory() as db:
        row = db.get(StudySession, session_id)
        return row is not None and row.ready_for_advice


def _stored(manager: SessionManager, session_id: int, index: int) -> Advice | None:
    with manager.factory() as db:
        return db.scalar(
            select(Advice).where(Advice.session_id == session_id, Advice.advice_index == index)
        )


def _receipt(
    stored: Advice, body: AdviceCreate, version: int, words: tuple[str, ...]
) -> AdviceReceipt:
    assert stored.action is not None, "a person's advice has its action (only replays lack one)"
    if stored.action != body.action:
        raise Conflict(
            f"advice {body.advice_index} was already given as {stored.action} "
            f"({words[stored.action]}); it cannot be changed"
        )
    return AdviceReceipt(
        advice_index=stored.advice_index,
        action=stored.action,
        duplicate=True,
        response_time_s=stored.response_time_s,
        version=version,
    )


async def submit_advice(
    manager: SessionManager, session: ParticipantSession, body: AdviceCreate
) -> AdviceReceipt:
    words = session.action_words
    if body.action >= len(words):
        raise Invalid("action", f"action must be one of this task's actions, 0 to {len(words) - 1}")
    handle = manager.handles.get(session.id)
    budget = session.advice_budget
    if handle is None:
        stored = await run_in_threadpool(_stored, manager, session.id, body.advice_index)
        if stored is not None:
            return _receipt(stored, body, manager.changes.version(session.id), words)
        _refuse_over_budget(body, budget)
        if not await run_in_threadpool(_ready, manager, session.id):
            raise Conflict(NOT_CONSENTED)
        status = Status(manager.status(session.id))
        raise Conflict(f"no advice can be taken now: {MESSAGES.get(status, '')}")
    live = handle.live
    async with live.advice_lock:
        if body.advice_index in live.given:
            stored = await run_in_threadpool(_stored, manager, session.id, body.advice_index)
            assert stored is not None, "advice given but not stored"
            return _receipt(stored, body, manager.changes.version(session.id), words)
        _refuse_over_budget(body, budget)
        if not live.ready:
            raise Conflict(NOT_CONSENTED)
        if live.status == Status.paused:
            raise Conflict("the session is paused by the researcher; advise when it resumes")
        request = live.request
        if request is None or live.status != Status.running:
            raise Conflict(
                "no advice is wanted right now (the learner is acting or is on its own); "
                "wait for the next observation from GET /api/participant/state"
            )
        if request.rated_action is not None:
            raise Conflict(
                "this turn asks for a rating of the action taken, not for advice: "
                "POST /api/participant/rating"
            )
        if request.advice_index != body.advice_index:
            raise Conflict(
                f"advice {request.advice_index} is wanted now, not {body.advice_index}; "
                "send advice_index from the latest state"
            )
        now = time.monotonic()
        response_time = live.response_time_s(now)
        answered_at = datetime.now(UTC)
        advice = AdviceGiven(
            session_id=session.id,
            advice_index=body.advice_index,
            global_step=request.global_step,
            advisor="human",
            action=body.action,
            greedy_action=request.greedy_action,
            observation_png=request.observation_png,
            response_time_s=response_time,
            decision_time_s=body.decision_time_s,
            requested_at=answered_at - timedelta(seconds=response_time),
            answered_at=answered_at,
            correct_action=request.correct.action,
            correct_actions=request.correct.stored,
        )
        stored = await run_in_threadpool(store_advice, manager.factory, advice)
        if stored is not None:
            return _receipt(stored, body, manager.changes.version(session.id), words)
        live.take_advice(HistoryEntry(body.advice_index, body.action, request.global_step))
        handle.send(AdviceAnswer(body.advice_index, body.action))
        manager.hub.publish(
            session.id, "advice_given", {"advice_index": body.advice_index, "action": body.action}
        )
        return AdviceReceipt(
            advice_index=body.advice_index,
            action=body.action,
            duplicate=False,
            response_time_s=response_time,
            version=manager.changes.version(session.id),
        )


def _refuse_over_budget(body: AdviceCreate, budget: int) -> None:
    if body.advice_index >= budget:
        raise Conflict(
            f"the advice budget of {budget} is spent (advice_index {body.advice_index} is "
            f"beyond it); the learner continues on its own, thank you"
        )
