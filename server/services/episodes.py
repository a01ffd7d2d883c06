"""The analysis package's episode table, read from the database.

One row per (session, training episode): the columns `server.analysis.episodes` documents.
Pretraining episodes are left out: the paper's curves and R_T count the training stage.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import pandas as pd
from sqlalchemy import select
from sqlalchemy.orm import Session

from learner import sb3_dqn
from learner.config import PRESETS, DQNConfig
from server.analysis.audit import describe_learner, describe_scenario
from server.analysis.rescoring import STEP_COLUMNS
from server.db.models import Episode, Step, StudySession
from server.services.learning import parse_scenario
from server.worker.recorder import TRAINING

EPISODE_TABLE_COLUMNS: tuple[str, ...] = (
    "session_id",
    "method",
    "seed",
    "episode",
    "collected_reward",
    "steps",
    "placed_correct",
    "misplaced",
    "lost",
    "epsilon",
)
"""The table's columns; `label` is left to the analysis (DeepRL1, agent-IDeepRL1, ... by
method and seed, so agents on the same seed share a number across methods)."""


def load_episodes(db: Session, session_ids: Sequence[int]) -> pd.DataFrame:
    """The training episodes of these sessions, ordered by session and episode."""
    query = (
        select(
            Episode.session_id,
            StudySession.method,
            StudySession.seed,
            Episode.episode,
            Episode.collected_reward,
            Episode.steps,
            Episode.placed_correct,
            Episode.misplaced,
            Episode.lost,
            Episode.epsilon,
        )
        .join(StudySession, StudySession.id == Episode.session_id)
        .where(Episode.session_id.in_(list(session_ids)), Episode.phase == TRAINING)
        .order_by(Episode.session_id, Episode.episode)
    )
    rows = [tuple(row) for row in db.execute(query)]
    return pd.DataFrame(rows, columns=list(EPISODE_TABLE_COLUMNS))


def load_training_steps(db: Session, session_ids: Sequence[int]) -> pd.DataFrame:
    """The training steps of these sessions (`server.analysis.rescoring.STEP_COLUMNS`)."""
    query = (
        select(Step.session_id, Step.episode, Step.episode_step, Step.reward, Step.terminated)
        .where(Step.session_id.in_(list(session_ids)), Step.phase == TRAINING)
        .order_by(Step.session_id, Step.global_step)
    )
    return pd.DataFrame([tuple(row) for row in db.execute(query)], columns=list(STEP_COLUMNS))


def session_settings(sessions: Sequence[StudySession]) -> pd.DataFrame:
    """What each session ran under, for the report's comparability audit
    (`server.analysis.audit.SETTINGS_COLUMNS`)."""
    presets = {name: DQNConfig.preset(name).to_dict() for name in PRESETS}
    rows = []
    for s in sessions:
        scenario = parse_scenario(s.scenario).to_dict()
        config, sb3 = sb3_dqn.split_config(s.config)
        learner = (
            sb3_dqn.describe(sb3, config)  # another learner altogether: the audit flags it
            if sb3
            else describe_learner(DQNConfig.from_dict(config).to_dict(), presets)
        )
        rows.append(
            {
                "session_id": s.id,
                "method": s.method,
                "reward_scheme": scenario["reward_scheme"],
                "learner": learner,
                "scenario": describe_scenario(scenario),
                "motion": s.motion,
                "sort_rule": json.dumps(s.sort_rule, sort_keys=True)
                if not isinstance(s.sort_rule, str)
                else s.sort_rule,
                "advice": "none"
                if s.strategy is None
                else f"{s.strategy}{_options(s.strategy_options)}, budget {s.advice_budget}",
            }
        )
    return pd.DataFrame(rows)


def _options(options: dict[str, Any] | None) -> str:
    """A strategy's options in words, e.g. " (interval 3)"; "" when it has none."""
    given = ", ".join(f"{k} {v}" for k, v in sorted((options or {}).items()))
    return f" ({given})" if given else ""
