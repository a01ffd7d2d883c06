"""What a participant's page calls, with the token from their link (one session only)."""

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from server.db.models import Outcome, StudySession
from server.deps import ManagerDep, ParticipantDep
from server.live import advising
from server.live.visits import end_visit
from server.routes.pages import visit_for_token
from server.schemas.participant import (
    AdviceCreate,
    AdviceReceipt,
    ConsentCreate,
    ConsentState,
    ParticipantState,
    Readiness,
)
from server.services import consent as consent_service
from server.services.errors import NotFound

router = APIRouter(prefix="/api/participant", tags=["participant"])
MAX_WAIT_S = 30.0


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
        await manager.wait_change(session.id, after, timeout)
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
        consent_service.finish_induction(db, row)


@router.post("/start")
async def start(session: ParticipantDep, manager: ManagerDep) -> ParticipantState:
    """The participant finished the induction (after consent; 409 before it): start the
    session if its link has not already, and let it ask for advice."""
    await run_in_threadpool(_finish_induction, manager, session.id)
    await manager.welcome(session.id)
    manager.set_ready(session.id)
    return await advising.current_state(manager, session)


@router.get("/readiness")
async def readiness(session: ParticipantDep, manager: ManagerDep) -> Readiness:
    """How far the robot's random pretraining is before the first turn; the advice page
    shows it while the robot is not ready yet. Starts the session if nobody has."""
    await manager.welcome(session.id)
    handle = manager.handles.get(session.id)
    if handle is None:
        state = await advising.current_state(manager, session)
        return Readiness(status=state.status, steps_done=0, steps_before_first_turn=0, ready=False)
    progress = handle.progress
    done = progress.global_step if progress is not None else 0
    waiting = progress is not None and progress.waiting_for_participant
    return Readiness(
        status=handle.status,
        steps_done=done,
        steps_before_first_turn=handle.steps_before_first_turn,
        ready=handle.request is not None or waiting or done >= handle.steps_before_first_turn,
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
    if wait > 0:
        await manager.wait_change(session.id, receipt.version, wait)
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
