"""Writes a worker's records to the database in batches, and keeps its checkpoints.

Exactly-once across crashes: rows are flushed before each checkpoint, and the checkpoint's
position (steps, episodes, advice) is saved with it. A resumed worker loads the checkpoint
and deletes the rows written after it; the learner's determinism then writes them again,
identically. Unique (session, index) constraints make any slip an error, never a double.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from sqlalchemy import delete, insert, update
from sqlalchemy.orm import Session, sessionmaker

from learner.records import TRAINING, EpisodeRecord, StepRecord
from study.db.models import Advice, Episode, Step, StudySession, utcnow
from study.services.advice import AdviceGiven, write_advice

STEP_COLUMNS = frozenset(c.name for c in Step.__table__.columns) - {"id"}
EPISODE_COLUMNS = frozenset(c.name for c in Episode.__table__.columns) - {"id"}


class LeaseLost(Exception):
    """Another worker took over this session (or it was deleted): stop writing at once."""


class Checkpointable(Protocol):
    def save_checkpoint(self, path: Path, *, memory: bool = ...) -> None: ...


def _row(
    record: StepRecord | EpisodeRecord, columns: frozenset[str], session_id: int
) -> dict[str, Any]:
    row = {k: v for k, v in record.to_dict().items() if k in columns}
    row["session_id"] = session_id
    row["wall_time"] = time.time()
    return row


class Recorder:
    """The trainer's callback that logs. `steps`: the last step logged (global steps count
    from 1); `episodes`: training episodes logged."""

    def __init__(
        self,
        factory: sessionmaker[Session],
        session_id: int,
        worker_token: str,
        checkpoint_dir: Path,
        flush_every_steps: int,
        heartbeat_s: float,
        progress: Callable[[], dict[str, Any]],
    ) -> None:
        self._factory = factory
        self.session_id = session_id
        self._token = worker_token
        self._dir = checkpoint_dir
        self._flush_every = flush_every_steps
        self._heartbeat_s = heartbeat_s
        self._progress = progress
        self._steps: list[dict[str, Any]] = []
        self._episodes: list[dict[str, Any]] = []
        self._advice: list[AdviceGiven] = []
        self._last_flush = time.monotonic()
        self.steps = 0
        self.episodes = 0
        self.advice = 0
        self.episodes_since_checkpoint = 0

    # --- learner callbacks -------------------------------------------------------------
    def on_step(self, record: StepRecord) -> None:
        self._steps.append(_row(record, STEP_COLUMNS, self.session_id))
        self.steps = record.global_step
        if len(self._steps) >= self._flush_every:
            self.flush()

    def on_episode(self, record: EpisodeRecord) -> None:
        self._episodes.append(_row(record, EPISODE_COLUMNS, self.session_id))
        if record.stage == TRAINING:
            self.episodes += 1
            self.episodes_since_checkpoint += 1
        self.flush()

    def add_advice(self, advice: AdviceGiven) -> None:
        """A machine advisor's advice, written at the next flush (a person's advice is
        written by the web process, complete, before the worker hears of it)."""
        self._advice.append(advice)

    # --- writing -----------------------------------------------------------------------
    def tick(self) -> None:
        """Between steps: flush and heartbeat when it is time."""
        if time.monotonic() - self._last_flush >= self._heartbeat_s:
            self.flush()

    def flush(self, **session_values: Any) -> None:
        with self._factory() as db:
            if self._steps:
                db.execute(insert(Step), self._steps)
            if self._episodes:
                db.execute(insert(Episode), self._episodes)
            write_advice(db, self._advice)
            self._own(db, heartbeat_at=utcnow(), progress=self._progress(), **session_values)
            db.commit()
        self._steps, self._episodes, self._advice = [], [], []
        self._last_flush = time.monotonic()

    def checkpoint(
        self, trainer: Checkpointable, advice_count: int, name: str = "", memory: bool = True
    ) -> Path:
        """Flush, save the learner, then record where it stands (in that order: a crash in
        between leaves the previous checkpoint in force, whose file we keep until now)."""
        self.flush()
        self._dir.mkdir(parents=True, exist_ok=True)
        path = self._dir / (name or f"step-{self.steps:09d}.pt")
        trainer.save_checkpoint(path, memory=memory)  # atomic: learner.checkpoint
        with self._factory() as db:
            self._own(
                db,
                checkpoint_path=str(path),
                checkpoint_step=self.steps,
                checkpoint_episodes=self.episodes,
                checkpoint_advice=advice_count,
            )
            db.commit()
        for old in self._dir.glob("step-*.pt"):
            if old != path:
                old.unlink(missing_ok=True)
        self.episodes_since_checkpoint = 0
        return path

    def rewind(self, session: StudySession) -> None:
        """Forget every row written after the checkpoint we resume from: steps and episodes
        past its global step, machine advice past its advice count."""
        self.steps = session.checkpoint_step
        self.episodes = session.checkpoint_episodes
        self.advice = session.checkpoint_advice
        sid = self.session_id
        with self._factory() as db:
            db.execute(delete(Step).where(Step.session_id == sid, Step.global_step > self.steps))
            db.execute(
                delete(Episode).where(
                    Episode.session_id == sid, Episode.last_global_step > self.steps
                )
            )
            if session.method != "human":
                db.execute(
                    delete(Advice).where(
                        Advice.session_id == sid, Advice.advice_index >= self.advice
                    )
                )
            self._own(db, heartbeat_at=utcnow())
            db.commit()

    def _own(self, db: Session, **values: Any) -> None:
        result = db.execute(
            update(StudySession)
            .where(StudySession.id == self.session_id, StudySession.worker_token == self._token)
            .values(**values)
        )
        if result.rowcount != 1:  # type: ignore[attr-defined]
            db.rollback()
            raise LeaseLost(f"session {self.session_id} is no longer this worker's")
