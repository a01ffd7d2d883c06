"""Studies (researcher key required). The services return rows and domain values; the
functions before the routes make them the API's responses (the dashboard's too)."""

from fastapi import APIRouter, BackgroundTasks, Path, Request, Response
from sqlalchemy import select
from starlette.concurrency import run_in_threadpool

from learner.fitted_ratings import model_from_json
from server.deps import DbDep, ManagerDep, ResearcherDep, SettingsDep
from server.live.manager import SessionManager
from server.routes.paging import PageDep
from server.routes.params import FittedId, StudyId
from server.routes.sessions import practise_ahead
from study.db.models import LIVE_STATUSES, FittedAdvisorModel, Status, Study, StudySession
from study.schemas.design import StudyDesign
from study.schemas.studies import (
    ConditionCounts,
    FittedAdvisorPublic,
    Preview,
    SessionDisk,
    StudyCreate,
    StudyDisk,
    StudyPublic,
    StudyUpdate,
)
from study.services import assignment, fitting, sessions, storage, studies
from study.services.errors import Conflict

router = APIRouter(prefix="/api/studies", tags=["studies"], dependencies=[ResearcherDep])


def study_public(study: Study, session_count: int, base_url: str) -> StudyPublic:
    """A study as the API shows it, with its number of sessions and its public link
    under `base_url` (online studies)."""
    update = {"session_count": session_count, "join_url": studies.join_url(study, base_url)}
    return StudyPublic.model_validate(study).model_copy(update=update)


def _public(db: DbDep, study: Study, base_url: str) -> StudyPublic:
    return study_public(study, studies.session_count(db, study.id), base_url)


def fitted_public(row: FittedAdvisorModel) -> FittedAdvisorPublic:
    """A fitted advisor (or evaluator) model, whole, with its summary."""
    return FittedAdvisorPublic(
        id=row.id,
        study_id=row.study_id,
        created_at=row.created_at,
        session_ids=[int(i) for i in row.session_ids],
        summary=model_from_json(row.model).summary(),
        model=row.model,
    )


def disk_public(use: storage.DiskUse) -> StudyDisk:
    """What a study keeps on disk (`storage.study_disk`), with its totals."""
    found = [SessionDisk(session_id=i, checkpoint_bytes=b) for i, b in use.session_bytes.items()]
    checkpoints = sum(use.session_bytes.values())
    return StudyDisk(
        study_id=use.study_id,
        total_bytes=checkpoints + use.report_bytes,
        checkpoint_bytes=checkpoints,
        report_bytes=use.report_bytes,
        sessions=found,
    )


@router.post("", status_code=201)
def create_study(db: DbDep, settings: SettingsDep, body: StudyCreate) -> StudyPublic:
    study = studies.create_study(
        db, body.name, description=body.description, texts=body.texts, design=body.design
    )
    storage.remove_study_files(settings.data_dir, study.id)  # left by a database reusing ids
    return _public(db, study, settings.base_url)


@router.get("")
def list_studies(db: DbDep, settings: SettingsDep, page: PageDep) -> list[StudyPublic]:
    return [_public(db, s, settings.base_url) for s in page.of(studies.list_studies(db))]


@router.get("/{study_id}")
def get_study(db: DbDep, settings: SettingsDep, study_id: StudyId) -> StudyPublic:
    return _public(db, studies.get_study(db, study_id), settings.base_url)


@router.patch("/{study_id}")
def update_study(
    db: DbDep, settings: SettingsDep, study_id: StudyId, body: StudyUpdate
) -> StudyPublic:
    changes = body.model_dump(exclude_unset=True, exclude={"design"})
    study = studies.update_study(db, study_id, **changes, design=body.design)
    return _public(db, study, settings.base_url)


@router.delete("/{study_id}", status_code=204)
async def delete_study(
    request: Request, db: DbDep, settings: SettingsDep, manager: ManagerDep, study_id: StudyId
) -> Response:
    """The study, its sessions and participants, their records, checkpoints, its report
    and exports; refused while a session runs, but for its pools' sessions, which nobody
    has yet: they end with their study. Its id is never given again."""
    studies.get_study(db, study_id)
    for tries_left in reversed(range(3)):  # the pools' keeper may start one meanwhile
        pooled = _live_pooled(db, manager, study_id)
        for session_id in pooled:
            await manager.end(session_id, Status.stopped, "its study was deleted")
        db.expire_all()
        live = {i for i in manager.handles if manager.status(i) in LIVE_STATUSES}
        try:
            checkpoints = settings.checkpoint_root
            await run_in_threadpool(
                storage.delete_study, db, settings.data_dir, study_id, live, checkpoints
            )
            break
        except Conflict:
            db.rollback()
            if not tries_left or not _live_pooled(db, manager, study_id):
                raise
    request.app.state.participant_tokens.clear()
    request.app.state.playbacks.close_deleted(db)
    return Response(status_code=204)


def _live_pooled(db: DbDep, manager: ManagerDep, study_id: int) -> list[int]:
    """The study's pooled sessions (kept for the next arrival) whose worker runs, here or
    on the Ray cluster."""
    pooled = db.scalars(
        select(StudySession.id).where(
            StudySession.study_id == study_id, StudySession.pooled.is_(True)
        )
    )
    return [
        i
        for i in pooled
        if ((live := manager.live(i)) is not None and live.status in LIVE_STATUSES)
        or manager.practising_elsewhere(i)
    ]


@router.get("/{study_id}/disk")
def study_disk(db: DbDep, settings: SettingsDep, study_id: StudyId) -> StudyDisk:
    """Bytes the study keeps on disk (checkpoints per session, report), beside its rows."""
    found = storage.study_disk(db, settings.data_dir, study_id, settings.checkpoint_root)
    return disk_public(found)


@router.get("/{study_id}/fitted")
def list_fitted_advisors(db: DbDep, study_id: StudyId) -> list[FittedAdvisorPublic]:
    """The advisor models fitted to the study's people (`ideeprl fit`), oldest first."""
    return [fitted_public(row) for row in fitting.list_models(db, study_id)]


@router.get("/{study_id}/fitted/{fitted_id}")
def get_fitted_advisor(db: DbDep, study_id: StudyId, fitted_id: FittedId) -> FittedAdvisorPublic:
    return fitted_public(fitting.get_model(db, study_id, fitted_id))


def _online(db: DbDep, study_id: int) -> tuple[Study, StudyDesign]:
    study = studies.get_study(db, study_id)
    design = studies.design_of(study)
    if design is None:
        raise Conflict(f"study {study_id} has no design: it is a lab study; PATCH one first")
    return study, design


@router.get("/{study_id}/conditions")
def condition_counts(db: DbDep, study_id: StudyId) -> list[ConditionCounts]:
    """An online study's conditions: target, completed, in progress, and the visits that
    ended early, by how (previews not counted)."""
    study, design = _online(db, study_id)
    tally = assignment.counts(db, study, design)
    return [ConditionCounts(condition=name, **vars(c)) for name, c in tally.items()]


@router.post("/{study_id}/preview", status_code=201)
def preview(
    db: DbDep,
    settings: SettingsDep,
    manager: ManagerDep,
    background: BackgroundTasks,
    study_id: StudyId,
) -> Preview:
    """A preview link: the researcher walks the study as a participant would (a session
    of the next condition, practised in its pool as an arrival's is, or practising from
    now), taking no place, kept out of exports and the report."""
    study, design = _online(db, study_id)
    with assignment.ARRIVALS:
        arrival = assignment.arrive(
            db,
            study,
            design,
            {},
            None,
            settings.data_dir,
            settings.worker_threads,
            preview=True,
        )
    assert arrival.token is not None, "a preview is never turned away"
    session = sessions.session_for_token(db, arrival.token)
    assert session is not None
    if arrival.session_id is not None:
        background.add_task(_assigned, manager, arrival.session_id)
    else:
        practise_ahead(background, manager, settings, session.id)
    return Preview(
        session_id=session.id,
        participant_url=sessions.participant_url(settings.base_url, arrival.token),
    )


async def _assigned(manager: SessionManager, session_id: int) -> None:
    """A pool's session given away: its idle limit runs from now (on the event loop, as
    the study link's arrivals have it)."""
    manager.assign(session_id)


async def _delete_sessions(
    request: Request, db: DbDep, settings: SettingsDep, manager: ManagerDep, ids: list[int]
) -> None:
    """Delete sessions, ending the live ones first (their visits are over)."""
    for session_id in ids:
        await manager.started_ahead(session_id)
        live = manager.live(session_id)
        if live is not None and live.status in LIVE_STATUSES:
            await manager.end(session_id, Status.stopped, "deleted by the researcher")
        db.expire_all()
        checkpoints = settings.checkpoint_root
        await run_in_threadpool(
            storage.delete_session, db, settings.data_dir, session_id, False, checkpoints
        )
    request.app.state.participant_tokens.clear()
    request.app.state.playbacks.close_deleted(db)


@router.delete("/{study_id}/preview", status_code=204)
async def delete_previews(
    request: Request, db: DbDep, settings: SettingsDep, manager: ManagerDep, study_id: StudyId
) -> Response:
    """Every preview session of the study, with all they recorded."""
    studies.get_study(db, study_id)
    ids = list(
        db.scalars(
            select(StudySession.id).where(
                StudySession.study_id == study_id, StudySession.preview.is_(True)
            )
        )
    )
    await _delete_sessions(request, db, settings, manager, ids)
    return Response(status_code=204)


@router.delete("/{study_id}/panel/{panel_id}", status_code=204)
async def delete_panel_person(
    request: Request,
    db: DbDep,
    settings: SettingsDep,
    manager: ManagerDep,
    study_id: StudyId,
    panel_id: str = Path(max_length=200, pattern=r"^[^\x00]+$"),
) -> Response:
    """Everything of the person with this panel id (their sessions, records, panel ids):
    how a participant's request to be forgotten is met."""
    ids = assignment.panel_person_sessions(db, study_id, panel_id)
    await _delete_sessions(request, db, settings, manager, ids)
    return Response(status_code=204)
