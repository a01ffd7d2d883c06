"""The analysis package's episode table, read from the database.

One row per (session, training episode): the columns `server.analysis.episodes` documents.
Pretraining episodes are left out: the paper's curves and R_T count the training stage.
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd
from sqlalchemy import select
from sqlalchemy.orm import Session

from server.db.models import Episode, StudySession
from server.sessions.recorder import TRAINING

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
