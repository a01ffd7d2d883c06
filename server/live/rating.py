"""A participant's evaluative feedback: the page shows the action the learner took and asks
for a rating, good or bad, within the run's time-out (`RunSpec.rating_time_out_s`).

The web process keeps the time-out's clock, from when the worker's request arrives: a rating
received before it is written to the `feedback` table, complete, and then forwarded to the
worker; at the time-out, no answer is written and forwarded instead. Either way the turn is
closed under the session's advice lock, so a rating is used exactly when it is stored, and
one outside the window is refused (409).
"""

from __future__ import annotations

import asyncio
import time
from datetime import UTC, datetime, timedelta

from sqlalchemy import select
from starlette.concurrency import run_in_threadpool

from learner.evaluators import BAD, GOOD
from learner.records import observation_hash
from runs.worker.messages import AdviceRequest, RatingAnswer
from server.live.manager import SessionManager
from server.live.session import HistoryEntry
from server.live.workers import WorkerHandle
from study.db.models import Feedback, Status, StudySession
from study.schemas.participant import ParticipantState, RatingCreate, RatingReceipt
from study.services.consent import NOT_CONSENTED
from study.services.errors import Conflict
from study.services.feedback import PERSON, FeedbackGiven, store_feedback
from study.services.observations import observation_of

JUDGEMENTS = {"good": GOOD, "bad": BAD}
EVALUATOR = PERSON
_TIMING_OUT: set[asyncio.Task[None]] = set()
_DEADLINES: dict[tuple[int, int], float] = {}
"""(session, turn) -> `time.monotonic()` after which its rating is refused: the request's
arrival plus the time-out, or a resume plus the time-out after a pause."""


def install(manager: SessionManager) -> None:
    """Ratings in `manager`'s sessions: each turn's time-out."""
    manager.on_request = lambda handle, request: asked(manager, handle, request)


def asked(manager: SessionManager, handle: WorkerHandle, request: AdviceRequest) -> None:
    """A turn's request arrived (on the event loop): a rating's time-out starts now."""
    if request.rated_action is None:
        return
    loop = asyncio.get_running_loop()
    key = (handle.session_id, request.advice_index)
    _DEADLINES[key] = time.monotonic() + request.rating_time_out_s

    def time_out() -> None:
        task = loop.create_task(_time_out(manager, handle, request))
        _TIMING_OUT.add(task)  # held until done (the loop keeps only a weak reference)
        task.add_done_callback(_TIMING_OUT.discard)

    loop.call_later(request.rating_time_out_s, time_out)


def shown(state: ParticipantState, request: AdviceRequest | None, arrived: float) -> None:
    """The state's rating fields, where the turn asks for a rating."""
    if request is None or request.rated_action is None:
        return
    state.rated_action = request.rated_action
    state.rated_reward = request.rated_reward
    state.rating_time_out_s = request.rating_time_out_s
    state.rating_left_s = max(0.0, _deadline(state.session_id, request, arrived) - time.monotonic())


def _deadline(session_id: int, request: AdviceRequest, arrived: float) -> float:
    default = arrived + request.rating_time_out_s
    return _DEADLINES.get((session_id, request.advice_index), default)


async def _time_out(manager: SessionManager, handle: WorkerHandle, request: AdviceRequest) -> None:
    index = request.advice_index
    live = handle.live
    if live.status == Status.paused:  # a whole time-out again once it goes on
        while live.status == Status.paused:
            await asyncio.sleep(0.2)
        if live.request is request and index not in live.given:
            asked(manager, handle, request)
            return
    async with live.advice_lock:
        if index in live.given or live.request is not request:
            _DEADLINES.pop((handle.session_id, index), None)
            return  # rated in time
        if live.status != Status.running:  # stopped or gone: a resumed worker asks again
            _DEADLINES.pop((handle.session_id, index), None)
            return
        _DEADLINES.pop((handle.session_id, index), None)
        response = live.response_time_s(time.monotonic())
        weight = await run_in_threadpool(_weight, manager, handle)
        given = _given(handle.session_id, request, None, weight, response, None)
        if not await run_in_threadpool(store_feedback, manager.factory, given):
            return
        _close(manager, handle, request, None)


def _given(
    session_id: int,
    request: AdviceRequest,
    judgement: float | None,
    weight: float,
    response_time_s: float,
    decision_time_s: float | None,
) -> FeedbackGiven:
    assert request.rated_action is not None
    answered_at = datetime.now(UTC)
    return FeedbackGiven(
        session_id=session_id,
        feedback_index=request.advice_index,
        global_step=request.global_step,
        evaluator=EVALUATOR,
        action=request.rated_action,
        judgement=judgement,
        shaping=0.0 if judgement is None else weight * judgement,
        greedy_action=request.greedy_action,
        observation_hash=observation_hash(observation_of(request.observation_png)),
        response_time_s=response_time_s,
        decision_time_s=decision_time_s,
        requested_at=answered_at - timedelta(seconds=response_time_s),
        answered_at=answered_at,
        correct_action=request.correct.action,
        correct_actions=request.correct.stored,
    )


def _close(
    manager: SessionManager, handle: WorkerHandle, request: AdviceRequest, judgement: float | None
) -> None:
    assert request.rated_action is not None
    index = request.advice_index
    handle.live.take_rating(
        HistoryEntry(index, request.rated_action, request.global_step, request.rated_reward),
        request.rated_reward,
    )
    handle.send(RatingAnswer(index, judgement))
    manager.hub.publish(handle.session_id, "rating_given", {"advice_index": index})


def _weight(manager: SessionManager, handle: WorkerHandle) -> float:
    if handle.seat.run is not None:
        return handle.seat.run.feedback_weight
    with manager.factory() as db:
        row = db.get(StudySession, handle.session_id)
        return row.spec.feedback_weight if row is not None else 1.0


def _stored(manager: SessionManager, session_id: int, index: int) -> Feedback | None:
    with manager.factory() as db:
        return db.scalar(
            select(Feedback).where(
                Feedback.session_id == session_id, Feedback.feedback_index == index
            )
        )


def _receipt(stored: Feedback, body: RatingCreate, version: int) -> RatingReceipt:
    if stored.judgement != JUDGEMENTS[body.rating]:
        said = "no answer (its time-out passed)" if stored.judgement is None else stored.judgement
        raise Conflict(f"turn {body.advice_index} was already rated: {said}; it cannot be changed")
    return RatingReceipt(
        advice_index=stored.feedback_index,
        action=stored.action,
        judgement=stored.judgement,
        shaping=stored.shaping,
        duplicate=True,
        response_time_s=stored.response_time_s,
        version=version,
    )


async def submit_rating(
    manager: SessionManager, session_id: int, body: RatingCreate
) -> RatingReceipt:
    handle = manager.handles.get(session_id)
    if handle is None or body.advice_index in handle.live.given:
        stored = await run_in_threadpool(_stored, manager, session_id, body.advice_index)
        if stored is not None:
            return _receipt(stored, body, manager.changes.version(session_id))
        if handle is None:
            raise Conflict("no rating can be taken now: the session is not running")
        raise Conflict(f"turn {body.advice_index} is over and was not a rating; it cannot be rated")
    live = handle.live
    async with live.advice_lock:
        if body.advice_index in live.given:
            stored = await run_in_threadpool(_stored, manager, session_id, body.advice_index)
            assert stored is not None, "a rating given but not stored"
            return _receipt(stored, body, manager.changes.version(session_id))
        if not live.ready:
            raise Conflict(NOT_CONSENTED)
        if live.status == Status.paused:
            raise Conflict("the session is paused by the researcher; rate when it resumes")
        request = live.request
        if request is None or request.rated_action is None or live.status != Status.running:
            raise Conflict(
                "no rating is wanted right now (the learner is acting on its own); "
                "wait for the next turn from GET /api/participant/state"
            )
        if request.advice_index != body.advice_index:
            raise Conflict(
                f"turn {request.advice_index} is to be rated now, not {body.advice_index}; "
                "send advice_index from the latest state"
            )
        now = time.monotonic()
        if now > _deadline(session_id, request, live.request_arrived):
            raise Conflict(
                f"the time to rate turn {body.advice_index} ({request.rating_time_out_s:g} s) "
                "is over: the learner went on with no answer"
            )
        response = live.response_time_s(now)
        judgement = JUDGEMENTS[body.rating]
        weight = await run_in_threadpool(_weight, manager, handle)
        given = _given(session_id, request, judgement, weight, response, body.decision_time_s)
        if not await run_in_threadpool(store_feedback, manager.factory, given):
            stored = await run_in_threadpool(_stored, manager, session_id, body.advice_index)
            assert stored is not None
            return _receipt(stored, body, manager.changes.version(session_id))
        _close(manager, handle, request, judgement)
        _DEADLINES.pop((session_id, body.advice_index), None)
        return RatingReceipt(
            advice_index=body.advice_index,
            action=given.action,
            judgement=judgement,
            shaping=given.shaping,
            duplicate=False,
            response_time_s=response,
            version=manager.changes.version(session_id),
        )
