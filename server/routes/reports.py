"""A study's report (the paper's analysis), built on request and served file by file."""

from __future__ import annotations

import shutil
from typing import Annotated

from fastapi import APIRouter, BackgroundTasks, Body
from fastapi import Path as PathParam
from fastapi.responses import FileResponse

from analysis.markdown import REPORT_FILE
from server.deps import DbDep, ResearcherDep, SettingsDep
from server.routes.params import StudyId
from study.schemas.reports import ReportCreate, ReportFile, ReportMethod, ReportPublic
from study.services import reports
from study.services.errors import Invalid, NotFound
from study.services.studies import get_study

router = APIRouter(prefix="/api/studies", tags=["reports"], dependencies=[ResearcherDep])

MEDIA_TYPES = {
    ".md": "text/markdown",
    ".png": "image/png",
    ".svg": "image/svg+xml",
    ".pdf": "application/pdf",
    ".csv": "text/csv",
}
FileName = Annotated[
    str, PathParam(pattern=r"^[A-Za-z0-9_.-]+$", max_length=100, description="A report file.")
]


def public_report(
    description: reports.ReportDescription, study_id: int, prefix: str = "/api/studies"
) -> ReportPublic:
    """The report's description with its files' URLs under `prefix` (the dashboard serves
    the same files behind its cookie)."""
    base = f"{prefix}/{study_id}/report"
    files = [
        ReportFile(name=f["name"], kind=f["kind"], url=f"{base}/files/{f['name']}")
        for f in description["files"]
    ]
    return ReportPublic(
        study_id=description["study_id"],
        created_at=description["created_at"],  # pydantic parses the ISO text
        sessions=description["sessions"],
        baseline=description["baseline"],
        n_episodes=description["n_episodes"],
        notes=description["notes"],
        methods=[ReportMethod(**m) for m in description["methods"]],
        files=files,
        report_url=f"{base}/files/{REPORT_FILE}",
        zip_url=f"{base}.zip",
    )


@router.post("/{study_id}/report", status_code=201)
def build_report(
    db: DbDep,
    settings: SettingsDep,
    study_id: StudyId,
    body: Annotated[ReportCreate | None, Body()] = None,
) -> ReportPublic:
    """Build (or rebuild) the study's report: Figures 5-7, R_T per agent and method, the
    improvement over the baseline, Student's t-tests, as PNG and CSV files and report.md."""
    body = body or ReportCreate()
    request = reports.ReportRequest(
        sessions=tuple(body.sessions) if body.sessions else None,
        methods=tuple(body.methods) if body.methods else None,
        label=body.label,
        baseline=body.baseline,
        n_episodes=body.n_episodes,
        title=body.title,
        allow_mismatch=body.allow_mismatch,
        reference=body.reference,
        primary=body.primary,
        choose=reports.API_CHOICE,
    )
    try:
        description = reports.publish_report(db, study_id, reports.reports_dir(settings), request)
    except Invalid as error:
        if error.field != "sessions":
            raise
        # ids that name no session of this study: nothing with that id, as for a path id
        lists = f"GET /api/studies/{study_id}/sessions lists them"
        raise NotFound(f"{error.message} ({lists})") from None
    return public_report(description, study_id)


@router.get("/{study_id}/report")
def get_report(db: DbDep, settings: SettingsDep, study_id: StudyId) -> ReportPublic:
    """The study's last report (404 until one is built)."""
    get_study(db, study_id)
    description = reports.published_report(reports.reports_dir(settings), study_id)
    return public_report(description, study_id)


@router.get(
    "/{study_id}/report/files/{name}",
    response_class=FileResponse,
    responses={200: {"content": {t: {} for t in MEDIA_TYPES.values()}}},
)
def get_report_file(
    db: DbDep, settings: SettingsDep, study_id: StudyId, name: FileName
) -> FileResponse:
    """One file of the study's last report, by the name its listing gives."""
    get_study(db, study_id)
    path = reports.report_file(reports.reports_dir(settings), study_id, name)
    return FileResponse(path, media_type=MEDIA_TYPES.get(path.suffix, "application/octet-stream"))


@router.get(
    "/{study_id}/report.zip",
    response_class=FileResponse,
    responses={200: {"content": {"application/zip": {}}}},
)
def get_report_zip(
    db: DbDep, settings: SettingsDep, study_id: StudyId, background: BackgroundTasks
) -> FileResponse:
    """Every file of the study's last report in one zip."""
    get_study(db, study_id)
    archive = reports.report_zip(
        reports.reports_dir(settings), study_id, settings.export_dir / "tmp"
    )
    background.add_task(shutil.rmtree, archive.parent, ignore_errors=True)
    return FileResponse(
        archive, media_type="application/zip", filename=f"study-{study_id}-report.zip"
    )
