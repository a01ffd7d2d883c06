"""What a participant's page calls, with the token from their link (one session only)."""

from collections.abc import Callable
from typing import TypeVar

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from server.deps import ManagerDep, ParticipantDep
from server.live import advising, rating
from server.live.trainers import shown_status
from server.live.visits import end_visit
from server.routes.pages import check_state, visit_for_token
from study.db.models import Outcome, StudySession
from study.schemas.participant import (
    AdviceCreate,
    AdviceReceipt,
    CheckCreate,
    CheckResult,
    CheckState,
    ConsentCreate,
    ConsentState,
    ParticipantState,
    QuestionnaireCreate,
    QuestionnaireState,
    RatingCreate,
    RatingReceipt,
    Readiness,
)
from study.services import consent as consent_service
from study.services import visit as visit_service
from study.services.errors import Conflict, NotFound
from study.services.visit import CheckGraded, QuestionnaireProgress

router = APIRouter(prefix="/api/participant", tags=["participant"])
MAX_WAIT_S = 30.0
T = TypeVar("T")


@router.get("/state")
async def get_state(
    session: ParticipantDep,
    manager: ManagerDep,
    after: int | None = Query(
        default=None, ge=0, description="Long-poll: wait until the version is newer than this."
    ),
    timeout: float = Query(default=20.0, ge=0.0, le=MAX_WAIT_S, description="Longest wait (s)."),
) -> ParticipantState:
    if after is not None:
        await manager.changes.wait(session.id, after, timeout)
    return await advising.current_state(manager, session)


def _consent_state(request: Request, session_id: int, record: ConsentCreate | None) -> ConsentState:
    """The texts shown (the stored version once consented), and any decision recorded."""
    with request.app.state.session_factory() as db:
        session = db.get(StudySession, session_id)
        if session is None or not session.participant_token:
            raise NotFound("this session no longer exists")
        visit = visit_for_token(request, session.participant_token)
        assert visit is not None, "a valid token has a visit"
        if session.consented_at is not None and session.texts_version is not None:
            version = session.texts_version
        else:
            version = consent_service.texts_version(db, visit.study_id, visit.resolved_texts())
        if record is not None:
            chosen = record.texts_version or version.id
            consent_service.record_decision(db, session, record.agree, chosen)
            db.refresh(session)
            version = session.texts_version or version
        return ConsentState(
            texts_version=version.id,
            texts=dict(version.texts),
            consented_at=session.consented_at,
            declined_at=session.declined_at,
            induction_done_at=session.induction_done_at,
        )


@router.get("/consent")
def get_consent(session: ParticipantDep, request: Request) -> ConsentState:
    """The consent and induction texts exactly as shown to this participant, with the id
    of their stored version (send it back with the decision)."""
    return _consent_state(request, session.id, None)


@router.post("/consent")
async def give_consent(
    session: ParticipantDep, request: Request, manager: ManagerDep, body: ConsentCreate
) -> ConsentState:
    """Consent (agree) or decline, recorded with the time and the texts version shown.
    Advice is asked only after consent and the induction (`POST /start`). In an online
    study a decline ends the visit (`declined`: its worker stopped, its place freed)."""
    state = await run_in_threadpool(_consent_state, request, session.id, body)
    if not body.agree and session.condition is not None and state.consented_at is None:
        await end_visit(manager, session.id, Outcome.declined)
    return state


def _finish_induction(manager: ManagerDep, session_id: int) -> None:
    with manager.factory() as db:
        row = db.get(StudySession, session_id)
        if row is None:
            raise NotFound("this session no longer exists")
        if not visit_service.check_passed(db, row):
            raise Conflict(
                "the comprehension check comes first: pass it (GET/POST "
                "/api/participant/check), then start"
            )
        consent_service.finish_induction(db, row)


@router.post("/start")
async def start(session: ParticipantDep, manager: ManagerDep) -> ParticipantState:
    """The participant finished the induction (after consent, and after an online study's
    comprehension check; 409 before them): start the session if its link has not already,
    and let it ask for advice."""
    await run_in_threadpool(_finish_induction, manager, session.id)
    await manager.welcome(session.id)
    manager.set_ready(session.id)
    return await advising.current_state(manager, session)


@router.get("/readiness")
async def readiness(session: ParticipantDep, manager: ManagerDep) -> Readiness:
    """How far the robot's random pretraining is before the first turn; the advice page
    shows it while the robot is not ready yet. Starts the session if nobody has."""
    await manager.welcome(session.id)
    live = manager.live(session.id)
    if live is None:
        return await run_in_threadpool(_stored_readiness, manager, session.id)
    progress = live.progress
    return Readiness(
        status=shown_status(manager.trainers, session.id, live.status)[0],
        steps_done=progress.global_step if progress is not None else 0,
        steps_before_first_turn=live.steps_before_first_turn,
        ready=live.at_first_turn,
    )


def _stored_readiness(manager: ManagerDep, session_id: int) -> Readiness:
    """The readiness of a session without a worker here, from its row: a pool's practice on
    the Ray cluster stores its progress there as it goes. It is ready once a worker here
    waits at its first turn."""
    with manager.factory() as db:
        row = db.get(StudySession, session_id)
        if row is None:
            raise NotFound("this session no longer exists")
        status, progress = row.status, row.progress or {}
        first_turn = row.spec.steps_before_first_turn()
    return Readiness(
        status=shown_status(manager.trainers, session_id, status)[0],
        steps_done=int(progress.get("global_step", 0)),
        steps_before_first_turn=first_turn,
        ready=False,
    )


@router.post("/advice")
async def give_advice(
    session: ParticipantDep,
    manager: ManagerDep,
    body: AdviceCreate,
    wait: float = Query(
        default=0.0,
        ge=0.0,
        le=MAX_WAIT_S,
        description="Seconds to wait for what happens next (the next request, usually) and "
        "return it as `state`: one round trip per advice.",
    ),
) -> AdviceReceipt:
    receipt = await advising.submit_advice(manager, session, body)
    last = not receipt.duplicate and receipt.advice_index + 1 >= session.advice_budget
    if last and await run_in_threadpool(_visit_ends_with_advice, manager, session.id):
        await end_visit(manager, session.id, Outcome.completed)
    if wait > 0:
        await manager.changes.wait(session.id, receipt.version, wait)
        receipt.state = await advising.current_state(manager, session)
    return receipt


@router.post("/rating")
async def give_rating(
    session: ParticipantDep,
    manager: ManagerDep,
    body: RatingCreate,
    wait: float = Query(
        default=0.0,
        ge=0.0,
        le=MAX_WAIT_S,
        description="Seconds to wait for what happens next (the next turn, usually) and "
        "return it as `state`.",
    ),
) -> RatingReceipt:
    """Evaluative feedback: rate the action the learner took on this turn, good or bad,
    within the run's time-out (409 outside it, or on a turn that asks for advice)."""
    receipt = await rating.submit_rating(manager, session.id, body)
    last = not receipt.duplicate and receipt.advice_index + 1 >= session.advice_budget
    if last and await run_in_threadpool(_visit_ends_with_advice, manager, session.id):
        await end_visit(manager, session.id, Outcome.completed)
    if wait > 0:
        await manager.changes.wait(session.id, receipt.version, wait)
        receipt.state = await advising.current_state(manager, session)
    return receipt


@router.get(
    "/observation.png", response_class=Response, responses={200: {"content": {"image/png": {}}}}
)
def observation(session: ParticipantDep, manager: ManagerDep) -> Response:
    png = advising.observation_png(manager, session)
    if png is None:
        raise NotFound("there is no observation yet; the session has not asked for advice")
    return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})


def _visit_ends_with_advice(manager: ManagerDep, session_id: int) -> bool:
    """An online study without a questionnaire completes the visit with the last advice."""
    with manager.factory() as db:
        row = db.get(StudySession, session_id)
        if row is None or visit_service.design_of(row) is None:
            return False
        return visit_service.questionnaire_of(row) is None and visit_service.advice_done(db, row)


def _with_session(
    manager: ManagerDep, session_id: int, act: Callable[[Session, StudySession], T]
) -> T:
    with manager.factory() as db:
        row = db.get(StudySession, session_id)
        if row is None:
            raise NotFound("this session no longer exists")
        return act(db, row)


def check_result(graded: CheckGraded) -> CheckResult:
    """A graded try: the check after it, and the ids of the questions answered wrong."""
    state = check_state(graded.progress)
    return CheckResult(**state.model_dump(), correct=graded.correct, wrong=graded.wrong)


def questionnaire_state(progress: QuestionnaireProgress) -> QuestionnaireState:
    return QuestionnaireState(
        required=progress.required,
        sections=progress.sections,
        available=progress.available,
        submitted_at=progress.submitted_at,
    )


@router.get("/check")
async def get_check(session: ParticipantDep, manager: ManagerDep) -> CheckState:
    """An online study's comprehension check (questions and choices, never the answers)
    and this participant's tries; `required` False for a lab study."""
    progress = await run_in_threadpool(
        _with_session, manager, session.id, visit_service.check_progress
    )
    return check_state(progress)


@router.post("/check")
async def answer_check(
    session: ParticipantDep, manager: ManagerDep, body: CheckCreate
) -> CheckResult:
    """One try at the check, graded under the session's sort rule. The last try wrong ends
    the visit as `excluded` (its worker stops); a pass lets `POST /start` go on."""
    graded = await run_in_threadpool(
        _with_session,
        manager,
        session.id,
        lambda db, row: visit_service.answer_check(db, row, body.answers),
    )
    if graded.progress.excluded:
        await end_visit(manager, session.id, Outcome.excluded)
    return check_result(graded)


@router.get("/questionnaire")
async def get_questionnaire(session: ParticipantDep, manager: ManagerDep) -> QuestionnaireState:
    """An online study's questionnaire (its sections and items), whether it may be
    answered yet (after the advice) and whether it was; `required` False for a lab study."""
    progress = await run_in_threadpool(
        _with_session, manager, session.id, visit_service.questionnaire_progress
    )
    return questionnaire_state(progress)


@router.post("/questionnaire")
async def submit_questionnaire(
    session: ParticipantDep, manager: ManagerDep, body: QuestionnaireCreate
) -> QuestionnaireState:
    """The questionnaire, once, after the advice: it completes the visit (the learner
    trains on; the completion never waits for it)."""
    progress = await run_in_threadpool(
        _with_session,
        manager,
        session.id,
        lambda db, row: visit_service.submit_questionnaire(db, row, body.answers),
    )
    await end_visit(manager, session.id, Outcome.completed)
    return questionnaire_state(progress)
