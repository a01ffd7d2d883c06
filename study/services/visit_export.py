"""The export's tables of an online study's visits: the comprehension check (one row per
question of each try), the questionnaire (one row per item) and its scored scales (one row
per scale and session, `study.schemas.instruments`). Sessions of a lab study have no rows.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from study.db.models import CheckAttempt, Outcome, QuestionnaireAnswer, StudySession
from study.schemas.instruments import SCALES

CHECK_COLUMNS: dict[str, tuple[str, str]] = {
    "session_id": ("integer", "Session of the participant who answered."),
    "attempt": ("integer", "Which try at the check, from 1 [count]."),
    "question": ("string", "The question's id in the design's check."),
    "text": ("string", "The question exactly as shown."),
    "answer": ("string", "The value of the choice the participant picked."),
    "expected": (
        "string",
        "The right choice's value, computed when answered (from the session's sort rule for "
        "a question about where an object goes).",
    ),
    "correct": ("boolean", "This question was answered right."),
    "result": (
        "string",
        "The try as a whole: passed (every answer right), retry (another try followed or "
        "may follow) or excluded (the last try wrong: the visit ended as excluded).",
    ),
    "answered_at": ("datetime", "When the try was sent (UTC)."),
}
QUESTIONNAIRE_COLUMNS: dict[str, tuple[str, str]] = {
    "session_id": ("integer", "Session of the participant who answered."),
    "instrument": (
        "string",
        "nasa_tlx (NASA-TLX raw), trust (Jian, Bisantz and Drury 2000), demographics, or "
        "custom (the researcher's own items).",
    ),
    "item": ("string", "The item's id within its instrument (e.g. mental, item_01, age)."),
    "text": ("string", "The item exactly as shown."),
    "value_number": (
        "number",
        "A numeric answer: a Likert point (1..points; trust 1-7 as answered, not reversed) "
        "or a number (NASA-TLX 0-100); empty for choices, text and skipped items.",
    ),
    "value_text": (
        "string",
        'A choice, free text, or "Prefer not to say"; empty for numbers and skipped items.',
    ),
    "answered_at": ("datetime", "When the questionnaire was submitted (UTC)."),
}
SCALE_COLUMNS: dict[str, tuple[str, str]] = {
    "session_id": ("integer", "Session of the participant who answered."),
    "scale": ("string", "nasa_tlx or trust."),
    "score": (
        "number",
        "nasa_tlx: the unweighted mean of the six subscales (raw TLX, 0-100, higher = more "
        "workload); trust: the mean of the twelve items after reversing the five distrust "
        "items (8 - answer; 1-7, higher = more trust). Empty unless every item was answered.",
    ),
    "items_answered": ("integer", "How many of the scale's items were answered [count]."),
}
VISIT_COLUMNS = {
    "check": CHECK_COLUMNS,
    "questionnaire": QUESTIONNAIRE_COLUMNS,
    "scales": SCALE_COLUMNS,
}
KEYS: dict[str, dict[str, Any]] = {
    "check": {"primaryKey": ["session_id", "attempt", "question"]},
    "questionnaire": {"primaryKey": ["session_id", "instrument", "item"]},
    "scales": {"primaryKey": ["session_id", "scale"]},
}


def check_rows(db: Session, sessions: list[StudySession]) -> Iterator[dict[str, Any]]:
    for session in sessions:
        query = select(CheckAttempt).where(CheckAttempt.session_id == session.id)
        attempts = list(db.scalars(query.order_by(CheckAttempt.attempt)))
        for a in attempts:
            last = a is attempts[-1]
            result = "passed" if a.correct else "retry"
            if not a.correct and last and session.outcome == Outcome.excluded:
                result = "excluded"
            for question, text in a.questions.items():
                yield {
                    "session_id": session.id,
                    "attempt": a.attempt,
                    "question": question,
                    "text": text,
                    "answer": a.answers.get(question),
                    "expected": a.expected.get(question),
                    "correct": a.answers.get(question) == a.expected.get(question),
                    "result": result,
                    "answered_at": a.answered_at,
                }


def _answers(db: Session, session_id: int) -> list[QuestionnaireAnswer]:
    query = select(QuestionnaireAnswer).where(QuestionnaireAnswer.session_id == session_id)
    return list(db.scalars(query.order_by(QuestionnaireAnswer.id)))


def questionnaire_rows(db: Session, sessions: list[StudySession]) -> Iterator[dict[str, Any]]:
    for session in sessions:
        for a in _answers(db, session.id):
            yield {name: getattr(a, name) for name in QUESTIONNAIRE_COLUMNS}


def scale_rows(db: Session, sessions: list[StudySession]) -> Iterator[dict[str, Any]]:
    """Each scored scale a session's questionnaire asked, scored from its stored answers."""
    for session in sessions:
        by_scale: dict[str, dict[str, float | None]] = defaultdict(dict)
        for a in _answers(db, session.id):
            if a.instrument in SCALES:
                by_scale[a.instrument][a.item] = a.value_number
        for scale, values in by_scale.items():
            yield {
                "session_id": session.id,
                "scale": scale,
                "score": SCALES[scale](values),
                "items_answered": sum(v is not None for v in values.values()),
            }


def visit_rows(db: Session, sessions: list[StudySession]) -> dict[str, Iterator[dict[str, Any]]]:
    return {
        "check": check_rows(db, sessions),
        "questionnaire": questionnaire_rows(db, sessions),
        "scales": scale_rows(db, sessions),
    }
