"""Studies: create, list, read, change, delete. An online study's design is checked here
(each condition's run as a session's would be) and stored with every default written out."""

from __future__ import annotations

import secrets

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from study.db.models import Study, StudySession
from study.schemas.design import StudyDesign
from study.schemas.studies import StudyCreate, StudyPublic, StudyUpdate
from study.services import learning
from study.services.errors import Conflict, Invalid, NotFound


def get_study(db: Session, study_id: int) -> Study:
    study = db.get(Study, study_id)
    if study is None:
        raise NotFound(f"no study with id {study_id}; GET /api/studies lists them")
    return study


def join_url(base_url: str, key: str) -> str:
    return f"{base_url}/join/{key}"


def public(db: Session, study: Study, base_url: str = "") -> StudyPublic:
    count = db.scalar(select(func.count()).where(StudySession.study_id == study.id)) or 0
    link = join_url(base_url, study.join_key) if study.join_key else None
    update = {"session_count": count, "join_url": link}
    return StudyPublic.model_validate(study).model_copy(update=update)


def stored_design(design: StudyDesign) -> dict[str, object]:
    """The design as stored: each condition's run checked and spelled out whole (a bad one
    is a 422 naming `design.conditions.NAME.run.FIELD`), every default written out."""
    for name, condition in design.conditions.items():
        try:
            spec = learning.parse(condition.run)
            if spec.method != "human":
                raise Invalid("run.method", "a condition's run is method human: people advise")
            learning.checked(spec)
        except Invalid as error:
            raise Invalid(f"design.conditions.{name}.{error.field}", error.message) from None
        condition.run = spec.to_json()
    return design.model_dump(mode="json")


def set_design(study: Study, design: StudyDesign) -> None:
    """Give the study its design, and its link and assignment seed the first time. A new
    design that names no codes keeps the study's (participants may hold them already)."""
    if study.design is not None and "codes" not in design.panel.model_fields_set:
        design.panel.codes = StudyDesign.model_validate(study.design).panel.codes
    study.design = stored_design(design)
    study.join_key = study.join_key or secrets.token_urlsafe(24)
    if study.assignment_seed is None:
        study.assignment_seed = secrets.randbelow(2**31)


def design_of(study: Study) -> StudyDesign | None:
    return None if study.design is None else StudyDesign.model_validate(study.design)


def create_study(db: Session, body: StudyCreate) -> Study:
    study = Study(**body.model_dump(exclude={"design"}))
    if body.design is not None:
        set_design(study, body.design)
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
    for field, value in body.model_dump(exclude_unset=True, exclude={"design"}).items():
        if value is not None:
            setattr(study, field, value)
    if body.design is not None:
        set_design(study, body.design)
    try:
        db.commit()
    except IntegrityError:
        db.rollback()
        raise Conflict(f"a study named {body.name!r} exists already; choose another name") from None
    return study
