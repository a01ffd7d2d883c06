"""An online study's visit around the advice: the comprehension check after the induction
and the questionnaire after the advice, over a session (`study.schemas.visit`).

A study without a design (a lab study) asks neither: every function here says so
(`required` False) and changes nothing. The check's right answers come from the session's
own sort rule when it is answered, and are stored beside the answers; each questionnaire
answer is stored with the item's text as shown. These answer with the dataclasses below;
the participant's routes build their responses from them (`server/routes/participant.py`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from sim.rules import SortRule
from study.db.models import (
    Advice,
    CheckAttempt,
    QuestionnaireAnswer,
    Status,
    StudySession,
)
from study.schemas.design import StudyDesign
from study.schemas.instruments import PREFER_NOT_TO_SAY
from study.schemas.participant import Answer
from study.schemas.visit import (
    CheckQuestion,
    CheckSpec,
    Choice,
    Item,
    QuestionnaireSpec,
    Section,
    default_questions,
)
from study.services.errors import Conflict, Invalid
from study.services.feedback import judgements_given
from tasks import CheckQuestion as TaskQuestion
from tasks import Task, get_task

NOT_CONSENTED = "consent first: the check comes after the consent and the induction"
VALUES = "abcdefgh"
"""A task question's choice values, in its order (a check question has at most 8)."""
MAX_TEXT = 2000
"""Longest free-text answer when an item sets no `max_length`."""


@dataclass(frozen=True)
class CheckProgress:
    """A session's comprehension check (`spec`, answers and all; None: the study asks none)
    and how far the participant is with it."""

    spec: CheckSpec | None
    tries_used: int = 0
    passed: bool = False

    @property
    def required(self) -> bool:
        return self.spec is not None

    @property
    def excluded(self) -> bool:
        """Every try failed: the visit has ended."""
        return self.spec is not None and not self.passed and self.tries_used >= self.spec.tries


@dataclass(frozen=True)
class CheckGraded:
    """One try at the check, graded: the check after it, and the ids of the questions it
    got wrong (none: every answer right)."""

    progress: CheckProgress
    wrong: list[str]

    @property
    def correct(self) -> bool:
        return not self.wrong


@dataclass(frozen=True)
class QuestionnaireProgress:
    """A session's questionnaire (its sections as the design has them; none asked:
    `required` False) and whether the participant may answer it, or did."""

    required: bool
    sections: list[Section] = field(default_factory=list)
    available: bool = False
    """The advice is done: it may be answered."""
    submitted_at: datetime | None = None


def design_of(session: StudySession) -> StudyDesign | None:
    """The session's study design; None for a lab study."""
    design = session.study.design
    return None if design is None else StudyDesign.model_validate(design)


def check_of(session: StudySession) -> CheckSpec | None:
    """The design's check; where the design keeps the default questions (the sorting
    robot's) and the session's task is another, that task's own questions instead."""
    design = design_of(session)
    if design is None or design.check is None:
        return None
    task = session.spec.task
    check = design.check
    if task != "sorting" and check.questions == default_questions():
        check = check.model_copy(update={"questions": task_questions(get_task(task))})
    if session.spec.feedback == "evaluative" and design.check.questions == default_questions():
        agent = session.spec.the_task.agent
        check = check.model_copy(update={"questions": [*check.questions, rating_question(agent)]})
    return check


RATINGS = (
    "Rate the move it just made: Good or Bad",
    "Choose its next move",
    "Nothing: I only watch",
)


def rating_question(agent: str) -> CheckQuestion:
    """The default check's question on what a person under evaluative feedback does."""
    return CheckQuestion(
        id="rating",
        text=f"When the {agent} asks for you, what do you do?",
        choices=[Choice(value=VALUES[i], label=c) for i, c in enumerate(RATINGS)],
        answer=VALUES[0],
    )


def task_questions(task: Task) -> list[CheckQuestion]:
    """A task's check questions in the design's form (choices valued a, b, c, ...); a task
    without any gets one on its goal."""
    goal = (task.goal or task.title)[:500]
    asked = task.check_questions or (
        TaskQuestion(
            "goal",
            f"What must the {task.agent} learn to do?",
            (goal, "Collect as few points as it can", "Nothing: it only watches"),
            goal,
        ),
    )
    return [
        CheckQuestion(
            id=q.id,
            text=q.text,
            choices=[Choice(value=VALUES[i], label=c) for i, c in enumerate(q.choices)],
            answer=VALUES[q.choices.index(q.answer)],
        )
        for q in asked
    ]


def questionnaire_of(session: StudySession) -> QuestionnaireSpec | None:
    design = design_of(session)
    return None if design is None else design.questionnaire


# --- the comprehension check -------------------------------------------------------------
def expected_answer(question: CheckQuestion, sort_rule: SortRule) -> str:
    """The right choice's value: fixed, or the object's side under the session's rule."""
    if question.side_of is None:
        assert question.answer is not None, "validated: one of answer, side_of"
        return question.answer
    shape, _, color = question.side_of.partition("/")
    return sort_rule.side(shape, color)


def _attempts(db: Session, session_id: int) -> list[CheckAttempt]:
    query = select(CheckAttempt).where(CheckAttempt.session_id == session_id)
    return list(db.scalars(query.order_by(CheckAttempt.attempt)))


def check_passed(db: Session, session: StudySession) -> bool:
    """No check to pass (a lab study, or a design without one), or one try all right."""
    if check_of(session) is None:
        return True
    return any(a.correct for a in _attempts(db, session.id))


def check_progress(db: Session, session: StudySession) -> CheckProgress:
    spec = check_of(session)
    if spec is None:
        return CheckProgress(None)
    attempts = _attempts(db, session.id)
    return CheckProgress(spec, len(attempts), any(a.correct for a in attempts))


def answer_check(db: Session, session: StudySession, answers: Mapping[str, str]) -> CheckGraded:
    """Grade one try and store it. 409 without a check, before consent, after a pass or
    once every try is spent; 422 for a missing answer, an unknown question or choice."""
    spec = check_of(session)
    if spec is None:
        raise Conflict("this study asks no comprehension check")
    if session.consented_at is None:
        raise Conflict(NOT_CONSENTED)
    state = check_progress(db, session)
    if state.passed:
        raise Conflict("the check was already passed; go on to the robot")
    if state.excluded:
        raise Conflict("every try of the check was used; the visit has ended")
    _validate_check_answers(spec, answers)
    rule = SortRule.parse(session.spec.sort_rule)
    expected = {q.id: expected_answer(q, rule) for q in spec.questions}
    wrong = [q.id for q in spec.questions if answers[q.id] != expected[q.id]]
    db.add(
        CheckAttempt(
            session_id=session.id,
            attempt=state.tries_used + 1,
            answers={q.id: answers[q.id] for q in spec.questions},
            expected=expected,
            questions={q.id: q.text for q in spec.questions},
            correct=not wrong,
        )
    )
    try:
        db.commit()
    except IntegrityError:  # the same try sent twice at once: the first one counts
        db.rollback()
        raise Conflict("this try was sent twice at once; reload the page") from None
    return CheckGraded(check_progress(db, session), wrong)


def _validate_check_answers(spec: CheckSpec, answers: Mapping[str, str]) -> None:
    known = {q.id: q for q in spec.questions}
    for key in answers:
        if key not in known:
            raise Invalid(f"answers.{key}", f"there is no question {key!r} in this check")
    for q in spec.questions:
        if q.id not in answers:
            raise Invalid(f"answers.{q.id}", f"answer question {q.id!r} too")
        values = [c.value for c in q.choices]
        if answers[q.id] not in values:
            raise Invalid(f"answers.{q.id}", f"{q.id!r} takes one of {', '.join(values)}")


# --- the questionnaire -------------------------------------------------------------------
def advice_done(db: Session, session: StudySession) -> bool:
    """The advice budget is spent (or the run finished): the questionnaire may come."""
    given = db.scalar(select(func.count()).where(Advice.session_id == session.id)) or 0
    given += judgements_given(db, session.id)  # a session's turns are advice or ratings
    return given >= session.spec.advice_budget or session.status == Status.finished


def _submitted_at(db: Session, session_id: int) -> datetime | None:
    query = select(func.max(QuestionnaireAnswer.answered_at))
    return db.scalar(query.where(QuestionnaireAnswer.session_id == session_id))


def questionnaire_progress(db: Session, session: StudySession) -> QuestionnaireProgress:
    spec = questionnaire_of(session)
    if spec is None:
        return QuestionnaireProgress(required=False)
    return QuestionnaireProgress(
        required=True,
        sections=spec.sections(session.spec.the_task.agent, session.spec.feedback),
        available=advice_done(db, session),
        submitted_at=_submitted_at(db, session.id),
    )


def submit_questionnaire(
    db: Session, session: StudySession, answers: Mapping[str, Mapping[str, Answer]]
) -> QuestionnaireProgress:
    """Store one row per item shown (an item skipped has no value). 409 without a
    questionnaire, before the advice is done, or a second time; 422 for an unknown item,
    a required item left out, or an answer the item does not take."""
    state = questionnaire_progress(db, session)
    if not state.required:
        raise Conflict("this study asks no questionnaire")
    if not state.available:
        raise Conflict("the questionnaire comes after the advice; give the advice first")
    if state.submitted_at is not None:
        raise Conflict("the questionnaire was already submitted")
    sections = {s.instrument: {i.id: i for i in s.items} for s in state.sections}
    for instrument, given in answers.items():
        for item_id in given:
            if item_id not in sections.get(instrument, {}):
                raise Invalid(
                    f"answers.{instrument}.{item_id}",
                    f"there is no item {instrument}.{item_id} in this questionnaire",
                )
    for instrument, items in sections.items():
        for item in items.values():
            value = answers.get(instrument, {}).get(item.id)
            number, text = _checked(item, value, f"answers.{instrument}.{item.id}")
            db.add(
                QuestionnaireAnswer(
                    session_id=session.id,
                    instrument=instrument,
                    item=item.id,
                    text=item.text,
                    value_number=number,
                    value_text=text,
                )
            )
    try:
        db.commit()
    except IntegrityError:  # the same form sent twice at once: the first stands
        db.rollback()
        raise Conflict("the questionnaire was already submitted") from None
    return questionnaire_progress(db, session)


def _checked(item: Item, value: Answer, field: str) -> tuple[float | None, str | None]:
    """The answer as (number, text) for storage, or a 422 saying what the item takes."""
    if isinstance(value, str) and not value.strip():
        value = None
    if value is None:
        if item.required:
            raise Invalid(field, f"{field.removeprefix('answers.')} must be answered")
        return None, None
    if item.prefer_not_to_say and value == PREFER_NOT_TO_SAY:
        return None, PREFER_NOT_TO_SAY
    takes = _takes(item)
    if item.kind == "choice":
        assert item.choices is not None
        if value not in item.choices:
            raise Invalid(field, f"not one of the choices; {takes}")
        return None, str(value)
    if item.kind == "text":
        if not isinstance(value, str) or len(value) > (item.max_length or MAX_TEXT):
            raise Invalid(field, takes)
        return None, value.strip()
    if isinstance(value, str):
        raise Invalid(field, takes)
    if item.kind == "likert":
        assert item.points is not None
        if not isinstance(value, int) or not 1 <= value <= item.points:
            raise Invalid(field, takes)
        return float(value), None
    assert item.minimum is not None and item.maximum is not None
    steps = (value - item.minimum) / item.step if item.step else 0.0
    on_grid = math.isclose(steps, round(steps), abs_tol=1e-9)
    if not item.minimum <= value <= item.maximum or not on_grid:
        raise Invalid(field, takes)
    return float(value), None


def _takes(item: Item) -> str:
    """What an item accepts, in words (for the 422)."""
    extra = f', or "{PREFER_NOT_TO_SAY}"' if item.prefer_not_to_say else ""
    if item.kind == "likert":
        return f"it takes a whole number from 1 to {item.points}{extra}"
    if item.kind == "choice":
        return f"it takes one of: {'; '.join(item.choices or [])}{extra}"
    if item.kind == "text":
        return f"it takes text of at most {item.max_length or MAX_TEXT} characters{extra}"
    step = f" in steps of {item.step:g}" if item.step else ""
    return f"it takes a number from {item.minimum:g} to {item.maximum:g}{step}{extra}"
