"""Studies: create, list, read, change, delete."""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from server.db.models import Study, StudySession
from server.schemas.studies import StudyCreate, StudyPublic, StudyUpdate
from server.services.errors import Conflict, NotFound


def get_study(db: Session, study_id: int) -> Study:
    study = db.get(Study, study_id)
    if study is None:
        raise NotFound(f"no study with id {study_id}; GET /api/studies lists them")
    return study


def public(db: Session, study: Study) -> StudyPublic:
    count = db.scalar(select(func.count()).where(StudySession.study_id == study.id)) or 0
    return StudyPublic.model_validate(study).model_copy(update={"session_count": count})


def create_study(db: Session, body: StudyCreate) -> Study:
    study = Study(**body.model_dump())
    db.add(study)
    try:
        db.commit()
    except IntegrityError:
        db.rollback()
        raise Conflict(f"a study named {body.name!r} exists already; choose another name") from None
    return study


def list_studies(db: Session) -> list[Study]:
    return list(db.scalars(select(Study).order_by(Study.id)))


def update_study(db: Session, study_id: int, body: StudyUpdate) -> Study:
    study = get_study(db, study_id)
    for field, value in body.model_dump(exclude_unset=True).items():
        if value is not None:
            setattr(study, field, value)
    try:
        db.commit()
    except IntegrityError:
        db.rollback()
        raise Conflict(f"a study named {body.name!r} exists already; choose another name") from None
    return study
