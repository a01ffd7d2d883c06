"""Studies (researcher key required)."""

from fastapi import APIRouter, Request, Response

from server.db.models import LIVE_STATUSES
from server.deps import DbDep, ManagerDep, ResearcherDep, SettingsDep
from server.routes.paging import PageDep
from server.routes.params import FittedId, StudyId
from server.schemas.studies import FittedAdvisorPublic, StudyCreate, StudyPublic, StudyUpdate
from server.services import fitting, storage, studies

router = APIRouter(prefix="/api/studies", tags=["studies"], dependencies=[ResearcherDep])


@router.post("", status_code=201)
def create_study(db: DbDep, settings: SettingsDep, body: StudyCreate) -> StudyPublic:
    study = studies.create_study(db, body)
    storage.remove_study_files(settings.data_dir, study.id)  # left by a database reusing ids
    return studies.public(db, study)


@router.get("")
def list_studies(db: DbDep, page: PageDep) -> list[StudyPublic]:
    return [studies.public(db, s) for s in page.of(studies.list_studies(db))]


@router.get("/{study_id}")
def get_study(db: DbDep, study_id: StudyId) -> StudyPublic:
    return studies.public(db, studies.get_study(db, study_id))


@router.patch("/{study_id}")
def update_study(db: DbDep, study_id: StudyId, body: StudyUpdate) -> StudyPublic:
    return studies.public(db, studies.update_study(db, study_id, body))


@router.delete("/{study_id}", status_code=204)
def delete_study(
    request: Request, db: DbDep, settings: SettingsDep, manager: ManagerDep, study_id: StudyId
) -> Response:
    """The study, its sessions and participants, their records, checkpoints, its report
    and exports; refused while a session runs. Its id is never given again."""
    live = {i for i, h in manager.handles.items() if h.status in LIVE_STATUSES}
    storage.delete_study(db, settings.data_dir, study_id, live)
    request.app.state.participant_tokens.clear()
    request.app.state.playbacks.close_deleted(db)
    return Response(status_code=204)


@router.get("/{study_id}/disk")
def study_disk(db: DbDep, settings: SettingsDep, study_id: StudyId) -> storage.StudyDisk:
    """Bytes the study keeps on disk (checkpoints per session, report), beside its rows."""
    return storage.study_disk(db, settings.data_dir, study_id)


@router.get("/{study_id}/fitted")
def list_fitted_advisors(db: DbDep, study_id: StudyId) -> list[FittedAdvisorPublic]:
    """The advisor models fitted to the study's people (`ideeprl fit`), oldest first."""
    return [fitting.public(row) for row in fitting.list_models(db, study_id)]


@router.get("/{study_id}/fitted/{fitted_id}")
def get_fitted_advisor(db: DbDep, study_id: StudyId, fitted_id: FittedId) -> FittedAdvisorPublic:
    return fitting.public(fitting.get_model(db, study_id, fitted_id))
