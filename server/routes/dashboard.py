"""The researchers' dashboard: a login form that sets an HttpOnly cookie (the key never
goes in a URL; the cookie holds a login that expires and that logout ends, `Logins`), a
page of studies and sessions with live learning curves, and the JSON the page polls.
Behind the same researcher key as the REST API, whose routes these reuse.

Requests that change something need the `X-Requested-With` header (a form on another
site cannot send it) on top of the SameSite=Strict cookie.
"""

from __future__ import annotations

import secrets
from typing import Annotated, Any, Literal

from fastapi import APIRouter, BackgroundTasks, Depends, Form, HTTPException, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from sqlalchemy import select

from learner.fields import FieldError
from learner.run import RunSpec
from server.deps import DbDep, ManagerDep, SettingsDep
from server.logins import Logins
from server.routes import exports as export_routes
from server.routes import reports as report_routes
from server.routes import sessions as session_routes
from server.routes import studies as study_routes
from server.routes.pages import templates
from server.routes.params import SessionId, StudyId
from server.routes.reports import FileName
from study.db.models import Episode, StudySession
from study.schemas.dashboard import (
    DashboardReport,
    NewDesign,
    NewParticipant,
    NewStudy,
    SessionRow,
    StudyRow,
)
from study.schemas.reports import ReportPublic
from study.schemas.sessions import SessionOptions
from study.schemas.studies import Preview
from study.services import assignment, reports, sessions, studies

COOKIE = "ideeprl_dashboard"
CSRF_HEADER = "X-Requested-With"
router = APIRouter(include_in_schema=False)


def _logins(request: Request) -> Logins:
    return request.app.state.dashboard_logins


def _logged_in(request: Request) -> bool:
    return _logins(request).valid(request.cookies.get(COOKIE, ""))


def require_login(request: Request) -> None:
    if not _logged_in(request):
        raise HTTPException(401, "log in to the dashboard first: /dashboard/login")
    if request.method != "GET" and not request.headers.get(CSRF_HEADER):
        raise HTTPException(403, f"changes need the {CSRF_HEADER} header (send them from the page)")


LoginDep = Depends(require_login)


# --- pages -------------------------------------------------------------------------------
def _login_page(request: Request, error: str = "", status: int = 200) -> HTMLResponse:
    response = templates.TemplateResponse(
        request, "dashboard/login.html", {"site_title": "IDeepRL dashboard", "error": error}
    )
    response.status_code = status
    return response


@router.get("/dashboard/login")
def login_form(request: Request) -> Response:
    return _login_page(request)


@router.post("/dashboard/login")
def login(request: Request, settings: SettingsDep, key: Annotated[str, Form()] = "") -> Response:
    assert settings.api_key, "the app always has a key"
    if not key or not secrets.compare_digest(key.encode(), settings.api_key.encode()):
        message = "That is not the researcher key. `ideeprl serve` prints it when it starts."
        return _login_page(request, message, 401)
    response = RedirectResponse("/dashboard", status_code=303)
    response.set_cookie(
        COOKIE,
        _logins(request).issue(),
        max_age=int(settings.dashboard_login_s),
        httponly=True,
        samesite="strict",
        # behind an HTTPS proxy the scheme comes from X-Forwarded-Proto (uvicorn trusts
        # the local proxy); a public https URL says so too
        secure=request.url.scheme == "https" or settings.base_url.startswith("https://"),
        path="/dashboard",
    )
    return response


@router.post("/dashboard/logout")
def logout(request: Request) -> Response:
    """Ends the login on the server: the cookie's value is refused from now on."""
    _logins(request).revoke(request.cookies.get(COOKIE, ""))
    response = RedirectResponse("/dashboard/login", status_code=303)
    response.delete_cookie(COOKIE, path="/dashboard")
    return response


@router.get("/", include_in_schema=False)
def root() -> Response:
    """The server's address alone leads to the dashboard (participants come by their own
    links, the API lives under /api and its reference at /docs)."""
    return RedirectResponse("/dashboard", status_code=303)


@router.get("/dashboard")
def dashboard(request: Request) -> Response:
    if not _logged_in(request):
        return RedirectResponse("/dashboard/login", status_code=303)
    return templates.TemplateResponse(
        request, "dashboard/dashboard.html", {"site_title": "IDeepRL dashboard"}
    )


# --- what the page polls and sends ------------------------------------------------------
@router.get("/dashboard/api/overview", dependencies=[LoginDep])
def overview(db: DbDep, settings: SettingsDep, manager: ManagerDep) -> list[StudyRow]:
    rows = []
    for study in studies.list_studies(db):
        found = []
        for session in sessions.list_sessions(db, study.id):
            public = session_routes.session_public(session, settings.base_url, manager)
            progress = session_routes.get_progress(db, manager, session.id)
            fields = public.model_dump(include=set(SessionRow.model_fields))
            fields.update(
                status=progress.status,
                progress=progress.model_dump(),
                declined=session.declined_at is not None and session.consented_at is None,
                node=session.worker_host,
            )
            found.append(SessionRow(**fields))
        counts = study_routes.condition_counts(db, study.id) if study.design else []
        rows.append(
            StudyRow(
                id=study.id,
                name=study.name,
                description=study.description,
                sessions=found,
                design=study.design,
                join_url=studies.join_url(study, settings.base_url),
                conditions=counts,
                report_built_at=reports.report_built_at(reports.reports_dir(settings), study.id),
            )
        )
    return rows


@router.post("/dashboard/api/studies/{study_id}/design", dependencies=[LoginDep])
def set_design(db: DbDep, study_id: StudyId, body: NewDesign) -> dict[str, Any]:
    """The study's design, whole (as `PATCH /api/studies/ID` with `design`)."""
    study = studies.update_study(db, study_id, design=body.design)
    return {"design": study.design}


@router.post("/dashboard/api/studies/{study_id}/preview", dependencies=[LoginDep], status_code=201)
def preview(
    db: DbDep,
    settings: SettingsDep,
    manager: ManagerDep,
    background: BackgroundTasks,
    study_id: StudyId,
) -> Preview:
    return study_routes.preview(db, settings, manager, background, study_id)


@router.delete("/dashboard/api/studies/{study_id}/preview", dependencies=[LoginDep])
async def delete_previews(
    request: Request, db: DbDep, settings: SettingsDep, manager: ManagerDep, study_id: StudyId
) -> Response:
    return await study_routes.delete_previews(request, db, settings, manager, study_id)


@router.get("/dashboard/api/studies/{study_id}/curves", dependencies=[LoginDep])
def curves(db: DbDep, study_id: StudyId) -> dict[int, list[tuple[int, float]]]:
    """Every session's learning curve: (episode, collected reward) per training episode."""
    studies.get_study(db, study_id)
    query = (
        select(Episode.session_id, Episode.episode, Episode.collected_reward)
        .join(StudySession, StudySession.id == Episode.session_id)
        .where(StudySession.study_id == study_id, Episode.stage == "train")
        .order_by(Episode.session_id, Episode.episode)
    )
    found: dict[int, list[tuple[int, float]]] = {}
    for session_id, episode, reward in db.execute(query):
        found.setdefault(session_id, []).append((episode, reward))
    return found


@router.post("/dashboard/api/sessions/{session_id}/{command}", dependencies=[LoginDep])
async def command(
    db: DbDep,
    settings: SettingsDep,
    manager: ManagerDep,
    session_id: SessionId,
    command: Literal["start", "pause", "resume", "stop"],
) -> dict[str, str]:
    session = sessions.get_session(db, session_id)
    if command == "start" and session.method == "human" and session.consented_at is None:
        raise HTTPException(
            409,
            f"session {session_id} waits for its participant's consent: their link shows the "
            "consent page and starts the session (the REST API can start it early)",
        )
    await getattr(manager, command)(session_id)
    return {"status": manager.status(session_id)}


@router.post("/dashboard/api/studies", dependencies=[LoginDep], status_code=201)
def new_study(db: DbDep, body: NewStudy) -> dict[str, int]:
    return {"id": studies.create_study(db, body.name).id}


@router.post(
    "/dashboard/api/studies/{study_id}/participants", dependencies=[LoginDep], status_code=201
)
def new_participant(
    db: DbDep,
    settings: SettingsDep,
    manager: ManagerDep,
    background: BackgroundTasks,
    study_id: StudyId,
    body: NewParticipant,
) -> dict[str, Any]:
    """A human session with the paper's settings, and its link to hand out; its random
    pretraining starts now (after the response), unless `pretrain` or the server's
    `pretrain_on_create` says otherwise."""
    try:
        options = SessionOptions(participant=body.participant or None)
    except FieldError as error:
        raise HTTPException(422, f"pseudonym: {error}") from None
    spec = assignment.numbered_seed(db, study_id, RunSpec(method="human"))
    created = sessions.create_session(
        db, study_id, spec, options, settings.data_dir, settings.worker_threads
    )
    public = session_routes.session_public(created, settings.base_url)
    if settings.pretrain_on_create if body.pretrain is None else body.pretrain:
        session_routes.practise_ahead(background, manager, settings, created.id)
    return {"id": created.id, "participant_url": public.participant_url}


@router.get("/dashboard/api/studies/{study_id}/export", dependencies=[LoginDep])
def export(
    db: DbDep, settings: SettingsDep, study_id: StudyId, background: BackgroundTasks
) -> FileResponse:
    return export_routes.export_study(db, settings, study_id, background)


# --- the study's report (the paper's analysis), as `POST /api/studies/ID/report` -------
DASHBOARD_STUDIES = "/dashboard/api/studies"


@router.post(f"{DASHBOARD_STUDIES}/{{study_id}}/report", dependencies=[LoginDep])
def build_report(
    db: DbDep, settings: SettingsDep, study_id: StudyId, body: DashboardReport | None = None
) -> ReportPublic:
    """The study's report over its finished sessions (advisors left out), against the
    baseline chosen (by default autonomous DeepRL when there is one). Sessions of different
    lengths are compared over the episodes they have in common (the report says so),
    unless `n_episodes`."""
    body = body or DashboardReport()
    request = reports.ReportRequest(
        n_episodes=body.n_episodes,
        common_length=body.n_episodes is None,
        baseline=body.baseline,
        choose=reports.dashboard_choice(study_id),
    )
    description = reports.publish_report(db, study_id, reports.reports_dir(settings), request)
    return report_routes.public_report(description, study_id, DASHBOARD_STUDIES)


@router.get(f"{DASHBOARD_STUDIES}/{{study_id}}/report", dependencies=[LoginDep])
def get_report(db: DbDep, settings: SettingsDep, study_id: StudyId) -> ReportPublic:
    studies.get_study(db, study_id)
    description = reports.published_report(reports.reports_dir(settings), study_id)
    return report_routes.public_report(description, study_id, DASHBOARD_STUDIES)


@router.get(f"{DASHBOARD_STUDIES}/{{study_id}}/report/files/{{name}}", dependencies=[LoginDep])
def get_report_file(
    db: DbDep, settings: SettingsDep, study_id: StudyId, name: FileName
) -> FileResponse:
    return report_routes.get_report_file(db, settings, study_id, name)


@router.get(f"{DASHBOARD_STUDIES}/{{study_id}}/report.zip", dependencies=[LoginDep])
def get_report_zip(
    db: DbDep, settings: SettingsDep, study_id: StudyId, background: BackgroundTasks
) -> FileResponse:
    return report_routes.get_report_zip(db, settings, study_id, background)
