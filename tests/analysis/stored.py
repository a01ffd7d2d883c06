"""A data folder as `serve` leaves it, for the analysis tests that go through the database
(`ideeprl report`, `ideeprl power`, `ideeprl export` then `python -m analysis`), and the
training episodes they store."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy.engine import Engine

from learner.records import TRAINING
from study.db.engine import make_engine
from study.db.migrate import upgrade
from study.db.models import Episode


def migrated_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Engine]:
    """`tmp_path/data` with a migrated SQLite database, and its engine (dispose it). A
    database URL in the environment would win over the folder, so the in-process commands
    run without one."""
    monkeypatch.delenv("DATABASE_URL", raising=False)
    monkeypatch.delenv("IDEEPRL_DATABASE_URL", raising=False)
    folder = tmp_path / "data"
    folder.mkdir()
    engine = make_engine(f"sqlite:///{folder / 'ideeprl.sqlite3'}")
    upgrade(engine)
    return folder, engine


def training_episode(session_id: int, number: int, reward: float) -> Episode:
    """A training episode's row: `reward` collected in 20 steps, nothing else of note."""
    return Episode(
        session_id=session_id, stage=TRAINING, episode=number, collected_reward=reward,
        steps=20, placed_correct=1, misplaced=0, lost=0, success=False, terminated=False,
        truncated=True, advised_steps=0, epsilon=0.5, mean_loss=None, first_global_step=0,
        last_global_step=19, wall_time=0.1, reset_seed=number,
    )  # fmt: skip
