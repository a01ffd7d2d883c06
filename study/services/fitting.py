"""Fitting advisors (or evaluators) to a study's people (`learner.fitted`,
`learner.fitted_ratings`), and keeping the models with it.

The advice rows say what was advised, not in which situation, nor what was right (and the
feedback rows what was rated, not whether the move was the right one): each advised (or
rated) episode is replayed from its reset seed and its logged actions (as
`study.services.outcomes` does), and the state before each advised step gives the
situation (the task's, or the step's stage within the correct action) and the task's
correct action. A model is stored in
`fitted_advisors` with the sessions it came from, and as a JSON file under the data
folder (`fitted/`) that a `fitted` run names. A study's sessions are fitted in one task.
Loads the simulator: run it from the command line (`ideeprl fit`), not in the web process.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from learner.fitted import AdviceSeen, SessionAdvice, fit, situation
from learner.fitted_ratings import (
    EVALUATIVE,
    AnyFitted,
    RatingSeen,
    SessionRatings,
    fit_ratings,
)
from learner.records import stage_of
from learner.seeding import reset_seeds
from study.db.models import (
    LIVE_STATUSES,
    Advice,
    Episode,
    Feedback,
    FittedAdvisorModel,
    Status,
    Step,
    StudySession,
)
from study.services.errors import Invalid, NotFound
from study.services.fitted_files import write_model_file
from study.services.outcomes import ReplayMismatch
from study.services.studies import get_study
from tasks import get_task

if TYPE_CHECKING:
    import gymnasium as gym

ENDED = (
    Status.finished,
    Status.stopped,
    Status.interrupted,
    Status.abandoned,
    Status.timed_out,
    Status.failed,
)
"""Sessions whose advice is over (an online visit that timed out, like an abandoned one,
may hold some); a running or paused one counts once its budget is spent
(it trains on without its advisor), never while its advisor may still give more."""
ADVISED = ("human", "oracle", "random", "agent", "fitted")


@dataclass(frozen=True)
class Fitted:
    """A stored model, and what the fit could not use."""

    id: int
    study_id: int
    path: Path
    """Its JSON file, what a `fitted` run's `fitted_model` names."""
    model: AnyFitted
    """An advisor's (`learner.fitted.FittedModel`) or an evaluator's
    (`learner.fitted_ratings.FittedEvaluatorModel`)."""
    without_situation: int
    """Advice (or rating turns) that could not be placed: its episode has no reset seed
    (recorded before they were kept), its step was not stored, or its task names no correct
    action there."""


def session_advice(db: Session, session: StudySession) -> tuple[SessionAdvice, int]:
    """One session's advice with their situations; and how many could not be placed."""
    spec = session.spec
    advice = list(
        db.scalars(
            select(Advice).where(Advice.session_id == session.id).order_by(Advice.advice_index)
        )
    )
    placed = _placed(db, session, {a.global_step for a in advice if a.action is not None})
    seen: list[AdviceSeen] = []
    for a in advice:
        if a.action is not None and a.global_step in placed:
            place, group, correct, rights = placed[a.global_step]
            # advice naming another right action (a move as short) is no error
            named = a.action if a.action in rights else correct
            seen.append(AdviceSeen(place, group, named, a.action, a.decision_time_s))
    found = SessionAdvice(session.id, seen, spec.advice_budget, given=len(advice))
    return found, len(advice) - len(seen)


def session_ratings(db: Session, session: StudySession) -> tuple[SessionRatings, int]:
    """One session's rating turns with their situations and whether the move rated was the
    correct action; and how many could not be placed."""
    query = select(Feedback).where(Feedback.session_id == session.id)
    turns = list(db.scalars(query.order_by(Feedback.feedback_index)))
    placed = _placed(db, session, {f.global_step for f in turns})
    seen: list[RatingSeen] = []
    for f in turns:
        if f.global_step in placed:
            place, group, _, rights = placed[f.global_step]
            right = f.action in rights
            seen.append(RatingSeen(place, group, right, f.judgement, f.decision_time_s))
    return SessionRatings(session.id, seen), len(turns) - len(seen)


Placed = tuple[str, str, int, tuple[int, ...]]
"""A step's situation (place, group), the task's correct action there and every action as
right (`tasks.Task.correct_actions`)."""


def _placed(db: Session, session: StudySession, wanted: set[int]) -> dict[int, Placed]:
    """The situation and correct action before each of these global steps that has them:
    each episode holding one replayed from its reset seed and its logged actions (a step
    whose episode has no reset seed, or whose task names no correct action, is left out)."""
    if not wanted:
        return {}
    spec = session.spec
    episodes = list(
        db.scalars(select(Episode).where(Episode.session_id == session.id).order_by(Episode.id))
    )
    placed: dict[int, Placed] = {}
    env = spec.make_env()
    try:
        for episode in episodes:
            here = {g for g in wanted if episode.first_global_step <= g <= episode.last_global_step}
            if here and episode.reset_seed is not None:
                first = episode.first_global_step
                placed.update(_replay(db, session, first, episode.reset_seed, here, env))
        # The episode a person left in (an abandoned session) has no record yet: its
        # steps are stored, and its reset seed is the run's next one.
        first = episodes[-1].last_global_step + 1 if episodes else 1
        here = {g for g in wanted if g >= first}
        if here and spec.learner == "dqn":
            reset_seed = reset_seeds(spec.seed, len(episodes) + 1)[-1]
            placed.update(_replay(db, session, first, reset_seed, here, env))
    finally:
        env.close()
    return placed


def _replay(
    db: Session,
    session: StudySession,
    first_step: int,
    reset_seed: int,
    wanted: set[int],
    env: gym.Env[Any, Any],
) -> dict[int, Placed]:
    steps = db.scalars(
        select(Step)
        .where(
            Step.session_id == session.id,
            Step.global_step.between(first_step, max(wanted)),
        )
        .order_by(Step.global_step)
    )
    task, options = session.spec.the_task, session.spec.env_options()
    _, info = env.reset(seed=reset_seed)
    placed = {}
    for step in steps:
        correct = task.correct_actions(info, options) if step.global_step in wanted else None
        if correct is not None and correct.action is not None:
            place, group = situation(task, info, stage_of(step.stage), correct.action)
            placed[step.global_step] = (place, group, correct.action, correct.actions)
        _, reward, _, _, info = env.step(step.action)
        if abs(float(reward) - step.reward) > 1e-9:
            raise ReplayMismatch(
                f"session {session.id}, step {step.global_step}: the replay's reward differs "
                "from the logged one"
            )
    return placed


def _budget_spent(db: Session, session: StudySession) -> bool:
    rows = Feedback if session.spec.feedback == EVALUATIVE else Advice
    given = db.scalar(select(func.count()).where(rows.session_id == session.id)) or 0
    return given >= session.spec.advice_budget


KINDS = ("advice", EVALUATIVE)
"""What a fit reads: the sessions' advice (an advisor), or their ratings (an evaluator)."""


def fit_study(
    db: Session,
    data_dir: Path,
    study_id: int,
    methods: Sequence[str] = ("human",),
    session_ids: Sequence[int] | None = None,
    kind: str | None = None,
) -> Fitted:
    """Fit the advisors (or, of evaluative sessions, the evaluators) of a study's sessions
    of these methods whose feedback is over (`ENDED`; or of the sessions named among them),
    store the model and write its file. `kind`: advice or evaluative; None, the one kind
    the sessions have."""
    get_study(db, study_id)
    unknown = sorted(set(methods) - set(ADVISED))
    if unknown or not methods:
        raise Invalid("methods", f"methods must be among the advised: {', '.join(ADVISED)}")
    if kind is not None and kind not in KINDS:
        raise Invalid("kind", f"kind must be {' or '.join(KINDS)}")
    query = select(StudySession).where(
        StudySession.study_id == study_id,
        StudySession.status.in_([s.value for s in (*ENDED, *LIVE_STATUSES)]),
        StudySession.preview.is_(False),  # a researcher's walk through is nobody's advice
    )
    sessions = [
        s
        for s in db.scalars(query.order_by(StudySession.id))
        if s.method in methods and (s.status in ENDED or _budget_spent(db, s))
    ]
    if session_ids is not None:
        sessions = [s for s in sessions if s.id in set(session_ids)]
    kinds = sorted({s.spec.feedback for s in sessions})
    if kind is None and len(kinds) > 1:
        raise Invalid(
            "kind",
            "the sessions gave advice and ratings; fit one kind (--kind advice or --kind "
            "evaluative)",
        )
    kind = kind or (kinds[0] if kinds else "advice")
    sessions = [s for s in sessions if s.spec.feedback == kind]
    model: AnyFitted
    if kind == EVALUATIVE:
        rated, lost = [], 0
        for session in sessions:
            ratings, missing = session_ratings(db, session)
            lost += missing
            if ratings.ratings:
                rated.append(ratings)
        fitted_ids = [r.session_id for r in rated]
    else:
        advised, lost = [], 0
        for session in sessions:
            advice, missing = session_advice(db, session)
            lost += missing
            if advice.advice:
                advised.append(advice)
        fitted_ids = [a.session_id for a in advised]
    if not fitted_ids:
        given = "ratings" if kind == EVALUATIVE else "advice"
        raise NotFound(
            f"study {study_id} has no {'/'.join(methods)} session with {given} to fit (a "
            f"session counts once its {given} are over; --methods human,oracle fits an "
            "oracle pilot too)"
        )
    tasks = sorted({s.spec.task for s in sessions if s.id in fitted_ids})
    if len(tasks) > 1:
        raise Invalid(
            "sessions",
            f"the sessions are of tasks {', '.join(tasks)}; fit one task's (--sessions)",
        )
    task = get_task(tasks[0])
    if kind == EVALUATIVE:
        model = fit_ratings(rated, methods, task=task)
    else:
        model = fit(advised, methods, task=task)
    row = FittedAdvisorModel(study_id=study_id, model=model.to_json(), session_ids=fitted_ids)
    db.add(row)
    db.commit()
    path = write_model_file(data_dir, row)
    return Fitted(row.id, study_id, path, model, lost)


def list_models(db: Session, study_id: int) -> list[FittedAdvisorModel]:
    get_study(db, study_id)
    query = select(FittedAdvisorModel).where(FittedAdvisorModel.study_id == study_id)
    return list(db.scalars(query.order_by(FittedAdvisorModel.id)))


def get_model(db: Session, study_id: int, model_id: int) -> FittedAdvisorModel:
    row = db.get(FittedAdvisorModel, model_id)
    if row is None or row.study_id != study_id:
        raise NotFound(
            f"study {study_id} has no fitted advisor {model_id}; "
            f"GET /api/studies/{study_id}/fitted lists them"
        )
    return row
