"""Studies (researcher key required)."""

from fastapi import APIRouter, Request, Response

from server.deps import DbDep, ResearcherDep
from server.routes.paging import PageDep
from server.routes.params import StudyId
from server.schemas.studies import StudyCreate, StudyPublic, StudyUpdate
from server.services import studies

router = APIRouter(prefix="/api/studies", tags=["studies"], dependencies=[ResearcherDep])


@router.post("", status_code=201)
def create_study(db: DbDep, body: StudyCreate) -> StudyPublic:
    return studies.public(db, studies.create_study(db, body))


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
def delete_study(request: Request, db: DbDep, study_id: StudyId) -> Response:
    studies.delete_study(db, study_id)
    request.app.state.participant_tokens.clear()
    return Response(status_code=204)
