"""The analysis package's episode table, read from the database.

One row per (session, training episode): the columns `analysis.episodes` documents.
Pretraining episodes are left out: the paper's curves and R_T count the training stage.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import pandas as pd
from sqlalchemy import select
from sqlalchemy.orm import Session

from analysis.advice import ADVICE_COLUMNS, REPLAYED_ADVICE_COLUMNS
from analysis.episodes import EPISODE_TABLE_COLUMNS, arm_of
from analysis.rescoring import STEP_COLUMNS
from analysis.settings import settings_table
from learner.records import TRAINING, stage_of
from study.db.models import Advice, Episode, Feedback, Step, StudySession
from tasks import actions_text

if TYPE_CHECKING:
    from analysis.human import Visits


def load_episodes(db: Session, session_ids: Sequence[int]) -> pd.DataFrame:
    """The training episodes of these sessions, ordered by session and episode."""
    ids = list(session_ids)
    runs = {  # the method as the report compares it: evaluative feedback an arm of its own
        s.id: (arm_of(s.spec), s.seed)
        for s in db.scalars(select(StudySession).where(StudySession.id.in_(ids)))
    }
    query = (
        select(
            Episode.session_id,
            Episode.episode,
            Episode.collected_reward,
            Episode.steps,
            Episode.placed_correct,
            Episode.misplaced,
            Episode.lost,
            Episode.success,
            Episode.epsilon,
        )
        .where(Episode.session_id.in_(ids), Episode.stage == TRAINING)
        .order_by(Episode.session_id, Episode.episode)
    )
    rows = [(r[0], *runs[r[0]], *r[1:]) for r in db.execute(query)]
    return pd.DataFrame(rows, columns=list(EPISODE_TABLE_COLUMNS))


def load_training_steps(db: Session, session_ids: Sequence[int]) -> pd.DataFrame:
    """The training steps of these sessions (`analysis.rescoring.STEP_COLUMNS`)."""
    query = (
        select(
            Step.session_id,
            Step.episode,
            Step.episode_step,
            Step.reward,
            Step.terminated,
            Step.outcome,
        )
        .where(Step.session_id.in_(list(session_ids)), Step.stage == TRAINING)
        .order_by(Step.session_id, Step.global_step)
    )
    rows = [tuple(row) for row in db.execute(query)]
    return pd.DataFrame(rows, columns=[*STEP_COLUMNS, "outcome"])


def load_advised_steps(db: Session, session_ids: Sequence[int]) -> pd.DataFrame:
    """The steps whose action came from the advisor (`analysis.advice.ADVICE_COLUMNS`)."""
    query = (
        select(
            Step.session_id,
            Step.global_step,
            Step.action,
            Step.outcome,
            Step.stage,
            Step.episode,
            Step.reward,
        )
        .where(Step.session_id.in_(list(session_ids)), Step.action_source == "advisor")
        .order_by(Step.session_id, Step.global_step)
    )
    rows = [tuple(row) for row in db.execute(query)]
    advised = pd.DataFrame(rows, columns=ADVICE_COLUMNS)
    return advised.assign(stage=advised["stage"].map(stage_of))


def load_replayed_advice(db: Session, session_ids: Sequence[int]) -> pd.DataFrame:
    """The advice rows of these sessions (`analysis.advice.REPLAYED_ADVICE_COLUMNS`): what a
    replay did with the stream it was fed."""
    query = (
        select(Advice.session_id, Advice.action, Advice.same_observation)
        .where(Advice.session_id.in_(list(session_ids)))
        .order_by(Advice.session_id, Advice.advice_index)
    )
    rows = [tuple(row) for row in db.execute(query)]
    return pd.DataFrame(rows, columns=REPLAYED_ADVICE_COLUMNS)


def load_visits(db: Session, sessions: Sequence[StudySession]) -> Visits:
    """What the participants of these sessions did (`analysis.human.Visits`), the tables
    the export writes, read from the database."""
    from analysis.human import Visits
    from study.services.visit_export import check_rows, questionnaire_rows, scale_rows

    visits = pd.DataFrame(
        [(s.id, s.condition, s.outcome, s.consented_at, s.status) for s in sessions],
        columns=["session_id", "condition", "outcome", "consented_at", "status"],
    )
    query = (
        select(
            Advice.session_id,
            Advice.advisor,
            Advice.action,
            Advice.decision_time_s,
            Advice.correct_action,
            Advice.correct_actions,
        )
        .where(Advice.session_id.in_([s.id for s in sessions]))
        .order_by(Advice.session_id, Advice.advice_index)
    )
    advice = pd.DataFrame(
        [(*row[:-1], actions_text(row[-1])) for row in db.execute(query)],
        columns=["session_id", "advisor", "action", "decision_time_s", "correct_action",
                 "correct_actions"],
    )  # fmt: skip
    rated = (
        select(
            Feedback.session_id,
            Feedback.evaluator,
            Feedback.action,
            Feedback.judgement,
            Feedback.decision_time_s,
            Feedback.correct_action,
            Feedback.correct_actions,
        )
        .where(Feedback.session_id.in_([s.id for s in sessions]))
        .order_by(Feedback.session_id, Feedback.feedback_index)
    )
    feedback = pd.DataFrame(
        [(*row[:-1], actions_text(row[-1])) for row in db.execute(rated)],
        columns=["session_id", "evaluator", "action", "judgement", "decision_time_s",
                 "correct_action", "correct_actions"],
    )  # fmt: skip
    check = pd.DataFrame(
        list(check_rows(db, list(sessions))),
        columns=["session_id", "attempt", "question", "correct"],
    )
    answers = pd.DataFrame(
        list(questionnaire_rows(db, list(sessions))),
        columns=["session_id", "instrument", "item", "value_number"],
    )
    scales = pd.DataFrame(
        list(scale_rows(db, list(sessions))), columns=["session_id", "scale", "score"]
    )
    return Visits(visits, advice, check, answers, scales, feedback)


def session_settings(
    sessions: Sequence[StudySession],
) -> pd.DataFrame:
    """What each session ran under, for the report's comparability audit
    (`analysis.settings.settings_table` of their runs)."""
    runs = [(s.id, s.spec) for s in sessions]
    return settings_table(runs, {s.id: s.provenance for s in sessions})
