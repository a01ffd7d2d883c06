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

from sqlalchemy import bindparam, delete, insert, update
from sqlalchemy.orm import Session, sessionmaker

from learner.records import TRAINING, EpisodeRecord, StepRecord
from study.db.models import Advice, Episode, Step, StudySession, utcnow

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
        advice_written_elsewhere: bool = False,
    ) -> None:
        """`advice_written_elsewhere`: a person's advice rows come from the web process;
        this recorder only completes them."""
        self._advice_written_elsewhere = advice_written_elsewhere
        self._factory = factory
        self.session_id = session_id
        self._token = worker_token
        self._dir = checkpoint_dir
        self._flush_every = flush_every_steps
        self._heartbeat_s = heartbeat_s
        self._progress = progress
        self._steps: list[dict[str, Any]] = []
        self._episodes: list[dict[str, Any]] = []
        self._advice: list[dict[str, Any]] = []
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

    def add_advice(self, row: dict[str, Any]) -> None:
        """A machine advisor's advice (human advice is written by the web process)."""
        self._advice.append({**row, "session_id": self.session_id})

    # --- writing -----------------------------------------------------------------------
    def tick(self) -> None:
        """Between steps: flush and heartbeat when it is time."""
        if time.monotonic() - self._last_flush >= self._heartbeat_s:
            self.flush()

    def flush(self, **session_values: Any) -> None:
        # Advice rows get the learner's greedy choice from the step they advised.
        greedy = {
            s["global_step"]: s["greedy_action"]
            for s in self._steps
            if s["action_source"] == "advisor"
        }
        for row in self._advice:
            row["greedy_action"] = greedy.get(row["global_step"], row["greedy_action"])
        with self._factory() as db:
            if greedy and self._advice_written_elsewhere:
                db.execute(
                    update(Advice.__table__)
                    .where(
                        Advice.__table__.c.session_id == self.session_id,
                        Advice.__table__.c.global_step == bindparam("step"),
                    )
                    .values(greedy_action=bindparam("greedy")),
                    [{"step": k, "greedy": v} for k, v in greedy.items()],
                )
            if self._steps:
                db.execute(insert(Step), self._steps)
            if self._episodes:
                db.execute(insert(Episode), self._episodes)
            if self._advice:
                db.execute(insert(Advice), self._advice)
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
