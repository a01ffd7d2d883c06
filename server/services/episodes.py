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
from learner.fields import leaves
from learner.run import RunSpec
from server.analysis.audit import describe_learner
from server.analysis.rescoring import STEP_COLUMNS
from server.db.models import Episode, Step, StudySession
from server.services import learning
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
    ids = list(session_ids)
    runs = {
        s.id: (s.method, s.seed)
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
            Episode.epsilon,
        )
        .where(Episode.session_id.in_(ids), Episode.phase == TRAINING)
        .order_by(Episode.session_id, Episode.episode)
    )
    rows = [(r[0], *runs[r[0]], *r[1:]) for r in db.execute(query)]
    return pd.DataFrame(rows, columns=list(EPISODE_TABLE_COLUMNS))


def load_training_steps(db: Session, session_ids: Sequence[int]) -> pd.DataFrame:
    """The training steps of these sessions (`server.analysis.rescoring.STEP_COLUMNS`)."""
    query = (
        select(Step.session_id, Step.episode, Step.episode_step, Step.reward, Step.terminated)
        .where(Step.session_id.in_(list(session_ids)), Step.phase == TRAINING)
        .order_by(Step.session_id, Step.global_step)
    )
    return pd.DataFrame([tuple(row) for row in db.execute(query)], columns=list(STEP_COLUMNS))


def session_settings(
    sessions: Sequence[StudySession], spec_class: type[RunSpec] = RunSpec
) -> pd.DataFrame:
    """What each session ran under, for the report's comparability audit: the learner (its
    preset and config, described), the treatment, and one column per other setting of the
    run's declaration (`spec_class`'s leaves of role `setting`), so a field added to the
    run is audited by itself (`server.analysis.audit`)."""
    presets = {name: DQNConfig.preset(name).to_dict() for name in PRESETS}
    settings = [
        leaf
        for leaf in leaves(spec_class)
        if leaf.role == "setting" and leaf.path[0] != "config" and leaf.name != "preset"
    ]
    rows = []
    for s in sessions:
        spec = learning.spec_of(s, spec_class).normalized()
        config = spec.config.to_dict()
        learner = (
            sb3_dqn.describe(spec.sb3, config)  # another learner altogether: the audit flags it
            if spec.learner == "sb3-dqn"
            else describe_learner(config, presets)
        )
        values = spec.values()
        rows.append(
            {
                "session_id": s.id,
                "method": s.method,
                "learner": learner,
                **{leaf.name: _text(values[leaf.name]) for leaf in settings},
                "advice": "none"
                if not spec.advised
                else f"{spec.strategy}{_options(spec.strategy_options.given())}, "
                f"budget {spec.advice_budget}",
            }
        )
    return pd.DataFrame(rows)


def _text(value: Any) -> Any:
    """A setting as the audit compares it (a map as sorted JSON)."""
    return json.dumps(value, sort_keys=True) if isinstance(value, dict | list) else value


def _options(options: dict[str, Any] | None) -> str:
    """A strategy's options in words, e.g. " (interval 3)"; "" when it has none."""
    given = ", ".join(f"{k} {v}" for k, v in sorted((options or {}).items()))
    return f" ({given})" if given else ""
