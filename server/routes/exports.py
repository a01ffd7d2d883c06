"""A study's export as one zip download."""

import shutil

from fastapi import APIRouter, BackgroundTasks
from fastapi.responses import FileResponse

from server.deps import DbDep, ResearcherDep, SettingsDep
from server.routes.params import StudyId
from server.services.export import export_zip

router = APIRouter(prefix="/api/studies", tags=["exports"], dependencies=[ResearcherDep])


@router.get(
    "/{study_id}/export",
    response_class=FileResponse,
    responses={200: {"content": {"application/zip": {}}}},
)
def export_study(
    db: DbDep, settings: SettingsDep, study_id: StudyId, background: BackgroundTasks
) -> FileResponse:
    """CSV files of sessions, episodes, steps and advice (with the advised images), and
    `columns.csv`, the column dictionary."""
    archive = export_zip(db, study_id, settings.export_dir / "tmp")
    background.add_task(shutil.rmtree, archive.parent, ignore_errors=True)
    return FileResponse(archive, media_type="application/zip", filename=f"study-{study_id}.zip")
