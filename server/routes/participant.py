"""What a participant's page calls, with the token from their link (one session only)."""

import contextlib

from fastapi import APIRouter, Query
from fastapi.responses import Response

from server.db.models import Status
from server.deps import ManagerDep, ParticipantDep
from server.schemas.participant import AdviceCreate, AdviceReceipt, ParticipantState
from server.services.errors import Conflict, NotFound
from server.sessions import advising

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
    return advising.participant_state(manager, session)


@router.post("/start")
async def start(session: ParticipantDep, manager: ManagerDep) -> ParticipantState:
    """Start the session when the participant is ready (after consent and induction);
    a session already under way is left as it is."""
    if session.id not in manager.handles and manager.status(session.id) == Status.created:
        with contextlib.suppress(Conflict):  # started by a second click meanwhile
            await manager.start(session.id)
    return advising.participant_state(manager, session)


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
        receipt.state = advising.participant_state(manager, session)
    return receipt


@router.get(
    "/observation.png", response_class=Response, responses={200: {"content": {"image/png": {}}}}
)
def observation(session: ParticipantDep, manager: ManagerDep) -> Response:
    png = advising.observation_png(manager, session)
    if png is None:
        raise NotFound("there is no observation yet; the session has not asked for advice")
    return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})
