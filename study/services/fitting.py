"""Fitting advisors to a study's people (`learner.fitted`), and keeping the models with it.

The advice rows say what was advised, not in which situation, nor what was right: each
advised episode is replayed from its reset seed and its logged actions (as
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

from learner.fitted import AdviceSeen, FittedModel, SessionAdvice, fit, situation
from learner.records import stage_of
from learner.seeding import reset_seeds
from study.db.models import (
    LIVE_STATUSES,
    Advice,
    Episode,
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
    model: FittedModel
    without_situation: int
    """Advice that could not be placed: its episode has no reset seed (recorded before
    they were kept), its step was not stored, or its task names no correct action there."""


def session_advice(db: Session, session: StudySession) -> tuple[SessionAdvice, int]:
    """One session's advice with their situations; and how many could not be placed."""
    spec = session.spec
    advice = list(
        db.scalars(
            select(Advice).where(Advice.session_id == session.id).order_by(Advice.advice_index)
        )
    )
    episodes = list(
        db.scalars(select(Episode).where(Episode.session_id == session.id).order_by(Episode.id))
    )
    seen: list[AdviceSeen] = []
    env = spec.make_env() if advice else None
    try:
        for episode in episodes:
            here = {
                a.global_step: a
                for a in advice
                if episode.first_global_step <= a.global_step <= episode.last_global_step
            }
            if here and episode.reset_seed is not None:
                assert env is not None
                first = episode.first_global_step
                seen += _replay(db, session, first, episode.reset_seed, here, env)
        # The episode a person left in (an abandoned session) has no record yet: its
        # steps are stored, and its reset seed is the run's next one.
        first = episodes[-1].last_global_step + 1 if episodes else 1
        here = {a.global_step: a for a in advice if a.global_step >= first}
        if here and spec.learner == "dqn":
            assert env is not None
            reset_seed = reset_seeds(spec.seed, len(episodes) + 1)[-1]
            seen += _replay(db, session, first, reset_seed, here, env)
    finally:
        if env is not None:
            env.close()
    found = SessionAdvice(session.id, seen, spec.advice_budget, given=len(advice))
    return found, len(advice) - len(seen)


def _replay(
    db: Session,
    session: StudySession,
    first_step: int,
    reset_seed: int,
    advice: dict[int, Advice],
    env: gym.Env[Any, Any],
) -> list[AdviceSeen]:
    task, options = session.spec.the_task, session.spec.env_options()
    steps = db.scalars(
        select(Step)
        .where(
            Step.session_id == session.id,
            Step.global_step.between(first_step, max(advice)),
        )
        .order_by(Step.global_step)
    )
    _, info = env.reset(seed=reset_seed)
    seen = []
    for step in steps:
        given = advice.get(step.global_step)
        correct = None if given is None else task.correct(info, options)
        if given is not None and given.action is not None and correct is not None:
            place, group = situation(task, info, stage_of(step.stage), correct)
            seen.append(AdviceSeen(place, group, correct, given.action, given.decision_time_s))
        _, reward, _, _, info = env.step(step.action)
        if abs(float(reward) - step.reward) > 1e-9:
            raise ReplayMismatch(
                f"session {session.id}, step {step.global_step}: the replay's reward differs "
                "from the logged one"
            )
    return seen


def _budget_spent(db: Session, session: StudySession) -> bool:
    given = db.scalar(select(func.count()).where(Advice.session_id == session.id)) or 0
    return given >= session.spec.advice_budget


def fit_study(
    db: Session,
    data_dir: Path,
    study_id: int,
    methods: Sequence[str] = ("human",),
    session_ids: Sequence[int] | None = None,
) -> Fitted:
    """Fit the advisors of a study's sessions of these methods whose advice is over (`ENDED`;
    or of the sessions named among them), store the model and write its file."""
    get_study(db, study_id)
    unknown = sorted(set(methods) - set(ADVISED))
    if unknown or not methods:
        raise Invalid("methods", f"methods must be among the advised: {', '.join(ADVISED)}")
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
    fitted, lost = [], 0
    for session in sessions:
        advice, missing = session_advice(db, session)
        lost += missing
        if advice.advice:
            fitted.append(advice)
    if not fitted:
        raise NotFound(
            f"study {study_id} has no {'/'.join(methods)} session with advice to fit (a "
            "session counts once its advice is over; --methods human,oracle fits an oracle "
            "pilot too)"
        )
    tasks = sorted({s.spec.task for s in sessions if any(f.session_id == s.id for f in fitted)})
    if len(tasks) > 1:
        raise Invalid(
            "sessions",
            f"the sessions are of tasks {', '.join(tasks)}; fit one task's (--sessions)",
        )
    model = fit(fitted, methods, task=get_task(tasks[0]))
    row = FittedAdvisorModel(
        study_id=study_id, model=model.to_json(), session_ids=[s.session_id for s in fitted]
    )
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
