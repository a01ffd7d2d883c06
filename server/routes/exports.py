"""A study's export as one zip download."""

import shutil
from typing import Annotated, Literal

from fastapi import APIRouter, BackgroundTasks, Query
from fastapi.responses import FileResponse

from server.deps import DbDep, ResearcherDep, SettingsDep
from server.routes.params import StudyId
from study.services.export import export_zip

router = APIRouter(prefix="/api/studies", tags=["exports"], dependencies=[ResearcherDep])


@router.get(
    "/{study_id}/export",
    response_class=FileResponse,
    responses={200: {"content": {"application/zip": {}}}},
)
def export_study(
    db: DbDep,
    settings: SettingsDep,
    study_id: StudyId,
    background: BackgroundTasks,
    format: Annotated[
        Literal["csv", "parquet"], Query(description="Tables as CSV (default) or Parquet.")
    ] = "csv",
    panel_ids: Annotated[
        bool,
        Query(
            description="An online study's panel ids as they are (for payment); without it "
            "they are pseudonymous (a keyed hash)."
        ),
    ] = False,
) -> FileResponse:
    """Tables of sessions, episodes, steps and advice (with the advised images), described
    by `datapackage.json` (Frictionless: each column's type, unit, description) and
    `columns.csv`, the same column dictionary."""
    archive = export_zip(db, study_id, settings.export_dir / "tmp", format, panel_ids)
    background.add_task(shutil.rmtree, archive.parent, ignore_errors=True)
    return FileResponse(archive, media_type="application/zip", filename=f"study-{study_id}.zip")
