"""An online study's public link, `/join/{key}`: arrivals get their session (assigned to a
condition, `study.services.assignment`) and go to their participant link; a full study
shows its page with the panel's "full" code. Rate-limited (`server.limits`)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import RedirectResponse, Response
from starlette.concurrency import run_in_threadpool

from server.routes.pages import end_page, participant_page, study_title
from study.db.models import Outcome
from study.schemas.design import StudyDesign
from study.services import assignment, studies
from study.services.errors import NotFound
from tasks import Task, get_task

router = APIRouter(include_in_schema=False)
COOKIE = "ideeprl_visit"
"""Holds an arrival's participant token, on the study link's path only: someone without a
panel id who comes back gets their own session again."""
COOKIE_DAYS = 30
MAX_PARAM = 200
"""Characters of a panel parameter (`panel_ids.panel_id` holds 200; Prolific's are 24)."""


def _too_many(what: str) -> Response:
    return Response(
        f"Too many arrivals {what}; please try again in a minute.",
        status_code=429,
        headers={"Retry-After": "60"},
        media_type="text/plain",
    )


Linked = tuple[int, StudyDesign, str]
"""A study link's study: its id, its design and its page title."""


@router.get("/join/{key}")
async def open_link(request: Request, key: str) -> Response:
    """An arrival from the panel (its id in the link) or coming back (the cookie) gets its
    session at once. Anyone else (the bare link: a link preview, a crawler, a person sent
    it without the panel) sees a page whose Begin button makes the session: a GET alone
    takes no place in the study."""
    try:
        linked = await run_in_threadpool(_linked, request, key)
    except NotFound:
        return _not_a_link(request)
    _, design, title = linked
    panel_id = request.query_params.get(design.panel.params[0], "").strip()
    if not panel_id and request.cookies.get(COOKIE) is None:
        query = request.url.query
        return participant_page(
            request,
            "participant/join.html",
            None,
            title,
            action=f"/join/{key}" + (f"?{query}" if query else ""),
            task=_task_or_none(design_task(design)),
        )
    return await _join(request, key, linked)


@router.post("/join/{key}")
async def join(request: Request, key: str) -> Response:
    return await _join(request, key, None)


async def _join(request: Request, key: str, linked: Linked | None) -> Response:
    """The arrival itself (`linked`: the link's study when the caller looked it up)."""
    settings = request.app.state.settings
    address = request.client.host if request.client is not None else "?"
    if not request.app.state.arrivals_by_address.allow(
        address, settings.join_per_address_per_minute
    ):
        return _too_many("from your address")
    if linked is None:
        try:
            linked = await run_in_threadpool(_linked, request, key)
        except NotFound:
            return _not_a_link(request)
    study_id, design, title = linked
    per_study = settings.join_per_place_per_minute * design.capacity
    if not request.app.state.arrivals_by_study.allow(key, per_study):
        return _too_many("at this study")
    params = dict(request.query_params)
    if any(len(v) > MAX_PARAM or "\x00" in v for v in params.values()):
        return Response(
            f"A parameter of this link is longer than {MAX_PARAM} characters or holds a NUL "
            "character; open the link as the panel gave it.",
            status_code=400,
            media_type="text/plain",
        )
    arrival = await run_in_threadpool(_arrive, request, study_id, params)
    if arrival.token is None:
        return end_page(request, None, design, Outcome.full, arrival.params, title)
    if arrival.session_id is not None:
        request.app.state.manager.assign(arrival.session_id)  # from a pool: its clock runs
    response = RedirectResponse(f"/p/{arrival.token}", status_code=303)
    response.set_cookie(
        COOKIE,
        arrival.token,
        max_age=COOKIE_DAYS * 86_400,
        httponly=True,
        samesite="lax",
        secure=request.url.scheme == "https" or settings.base_url.startswith("https://"),
        path=f"/join/{key}",
    )
    return response


def _not_a_link(request: Request) -> Response:
    """The participant's page for a link that is not valid, as for a session's link."""
    response = participant_page(request, "participant/error.html", None, looked_for="a study")
    response.status_code = 404
    return response


def design_task(design: StudyDesign) -> str | None:
    """The task the study link's conditions share (the pages' words before a session
    exists); None when they name different ones."""
    named = {str(c.run.get("task", "sorting")) for c in design.conditions.values()}
    return named.pop() if len(named) == 1 else None


def _task_or_none(name: str | None) -> Task | None:
    return None if name is None else get_task(name)


def _linked(request: Request, key: str) -> Linked:
    with request.app.state.session_factory() as db:
        study, design = assignment.study_for_key(db, key)
        return study.id, design, study_title(study.texts, design_task(design))


def _arrive(request: Request, study_id: int, params: dict[str, str]) -> assignment.Arrival:
    state = request.app.state
    with assignment.ARRIVALS, state.session_factory() as db:
        study = studies.get_study(db, study_id)
        design = studies.design_of(study)
        assert design is not None, "a study with a link has a design"
        return assignment.arrive(
            db,
            study,
            design,
            params,
            request.cookies.get(COOKIE),
            state.settings.data_dir,
            state.settings.worker_threads,
        )
