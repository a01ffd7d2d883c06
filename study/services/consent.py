"""Consent on the server: the exact texts a participant read, and what they decided.

A human session's participant must consent, then finish the induction, before anyone may
ask them for advice; whoever started the session (its link, the API, the dashboard) this
is checked here, not in the browser. The texts are stored once per distinct content
(`StudyTexts`, keyed by a hash): a session points at the version its participant saw, and
editing a study's texts after sessions ran makes a new version, leaving the old ones.
"""

from __future__ import annotations

import hashlib
import json

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from study.db.models import StudySession, StudyTexts, utcnow
from study.services.errors import Conflict, Invalid

NOT_CONSENTED = (
    "the participant has not consented yet: their link shows the consent page first, and "
    "advice is asked only after consent and the induction"
)


def content_hash(texts: dict[str, str]) -> str:
    return hashlib.sha256(json.dumps(texts, sort_keys=True).encode()).hexdigest()


def texts_version(db: Session, study_id: int, texts: dict[str, str]) -> StudyTexts:
    """The stored version of these texts, made when they were never shown before."""
    digest = content_hash(texts)
    query = select(StudyTexts).where(
        StudyTexts.study_id == study_id, StudyTexts.content_hash == digest
    )
    for _ in range(5):  # two first visits at once: one insert wins, the other reads it
        found = db.scalar(query)
        if found is not None:
            return found
        latest = db.scalar(
            select(func.max(StudyTexts.version)).where(StudyTexts.study_id == study_id)
        )
        row = StudyTexts(
            study_id=study_id, version=(latest or 0) + 1, content_hash=digest, texts=dict(texts)
        )
        db.add(row)
        try:
            db.commit()
            return row
        except IntegrityError:
            db.rollback()
    raise Conflict("the study's texts changed many times at once; reload the page")


def record_decision(
    db: Session, session: StudySession, agree: bool, version_id: int | None
) -> StudySession:
    """Consent (`agree`) or decline, with the time and the texts version shown.

    The first consent stands (a second click changes nothing); a decline is recorded even
    after an earlier one, and a participant who declined may still consent later, in a lab
    session; an online visit that has ended (declined, excluded, timed out) takes no
    decision any more."""
    if session.outcome is not None and session.consented_at is None:
        raise Conflict(f"this visit has ended ({session.outcome}); it takes no consent now")
    if version_id is not None:
        version = db.get(StudyTexts, version_id)
        if version is None or version.study_id != session.study_id:
            raise Invalid("texts_version", f"no texts version {version_id} in this study")
        shown = version.id
    else:
        shown = None
    now = utcnow()
    if agree:
        if session.consented_at is None:
            session.consented_at = now
            session.texts_version_id = shown or session.texts_version_id
    else:
        if session.consented_at is not None:
            raise Conflict(
                "consent was already given; to withdraw, tell the researcher, who can stop "
                "the session"
            )
        session.declined_at = now
        session.texts_version_id = shown or session.texts_version_id
    db.commit()
    return session


def finish_induction(db: Session, session: StudySession) -> StudySession:
    """The participant finished the induction: from now on they may be asked for advice."""
    if session.consented_at is None:
        raise Conflict(NOT_CONSENTED)
    if session.induction_done_at is None:
        session.induction_done_at = utcnow()
        db.commit()
    return session
