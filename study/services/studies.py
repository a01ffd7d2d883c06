"""Studies: create, list, read, change, delete. An online study's design is checked here
(each condition's run as a session's would be) and stored with every default written out.

Like every service, these take domain values (a name, texts, a `StudyDesign`), never a
REST body: the routes, the dashboard and the command line read their own bodies and call
the same functions."""

from __future__ import annotations

import secrets
from collections.abc import Mapping
from typing import Any

from pydantic import TypeAdapter, ValidationError
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from learner.fields import FieldError
from learner.run import RunSpec, declared
from study.db.models import Study, StudySession
from study.schemas.design import StudyDesign
from study.schemas.types import StudyName
from study.services.errors import Conflict, Invalid, NotFound


def get_study(db: Session, study_id: int) -> Study:
    study = db.get(Study, study_id)
    if study is None:
        raise NotFound(f"no study with id {study_id}; GET /api/studies lists them")
    return study


def join_url(study: Study, base_url: str) -> str | None:
    """An online study's public link under `base_url`; None for a lab study."""
    return f"{base_url}/join/{study.join_key}" if study.join_key else None


def session_count(db: Session, study_id: int) -> int:
    return db.scalar(select(func.count()).where(StudySession.study_id == study_id)) or 0


def condition_run(name: str, run: Any) -> RunSpec:
    """Condition `name`'s run checked as a study stores it: a human run, every value valid
    (a bad one is `Invalid` naming `design.conditions.NAME.run.FIELD`)."""
    where = f"design.conditions.{name}.run"
    try:
        spec = declared().from_json(run)
        if spec.method != "human":
            raise Invalid(f"{where}.method", "a condition's run is method human: people advise")
        spec.validate().pinned()
    except FieldError as error:
        field = f"{where}.{error.field}" if error.field else where
        raise Invalid(field, str(error)) from None
    return spec


def stored_design(design: StudyDesign) -> dict[str, object]:
    """The design as stored: each condition's run checked (`condition_run`) and spelled out
    whole, every default written out."""
    for name, condition in design.conditions.items():
        condition.run = condition_run(name, condition.run).to_json()
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


def create_study(
    db: Session,
    name: str,
    *,
    description: str = "",
    texts: Mapping[str, str] | None = None,
    design: StudyDesign | None = None,
) -> Study:
    """A new study; with a `design`, an online one (its link and assignment seed made)."""
    name = valid_name(name)
    study = Study(name=name, description=description, texts=dict(texts or {}))
    if design is not None:
        set_design(study, design)
    db.add(study)
    _commit(db, name)
    return study


_NAME = TypeAdapter(StudyName)


def valid_name(name: str) -> str:
    """A study's name as stored (`StudyName`: spaces around it dropped, not blank, at most
    200 characters, text a database can hold), whoever gives it: the API, a design file,
    `ideeprl batch --study NAME`."""
    try:
        return _NAME.validate_python(name)
    except ValidationError as error:
        raise Invalid("name", f"the study's name: {error.errors()[0]['msg']}") from None


def _commit(db: Session, name: str | None) -> None:
    try:
        db.commit()
    except IntegrityError:
        db.rollback()
        raise Conflict(f"a study named {name!r} exists already; choose another name") from None


def list_studies(db: Session) -> list[Study]:
    return list(db.scalars(select(Study).order_by(Study.id)))


def update_study(
    db: Session,
    study_id: int,
    *,
    name: str | None = None,
    description: str | None = None,
    texts: Mapping[str, str] | None = None,
    design: StudyDesign | None = None,
) -> Study:
    """Change what is given (None: keep it); a new design replaces the old one whole."""
    study = get_study(db, study_id)
    if name is not None:
        study.name = name = valid_name(name)
    if description is not None:
        study.description = description
    if texts is not None:
        study.texts = dict(texts)
    if design is not None:
        _keeps_conditions_in_use(db, study, design)
        set_design(study, design)
    _commit(db, name)
    return study


def _keeps_conditions_in_use(db: Session, study: Study, design: StudyDesign) -> None:
    """A new design may not drop a condition that has sessions: its participants' data
    would lose the arm it belongs to (lower its target to close it instead)."""
    old = set((study.design or {}).get("conditions", {}))
    dropped = sorted(old - set(design.conditions))
    if not dropped:
        return
    query = (
        select(StudySession.condition, func.count())
        .where(StudySession.study_id == study.id, StudySession.condition.in_(dropped))
        .where(StudySession.preview.is_(False))
        .group_by(StudySession.condition)
    )
    used = {condition: count for condition, count in db.execute(query)}
    if used:
        listed = ", ".join(f"{name!r} ({n} session{'s' * (n != 1)})" for name, n in used.items())
        raise Conflict(
            f"the new design drops condition(s) that have sessions: {listed}; keep them "
            "(lower a target to its completed count to close it) or start a new study"
        )
