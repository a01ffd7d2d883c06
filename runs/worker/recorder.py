"""What a run tells, as the trainer's callbacks: `Recorder` writes its records to the
database in batches and keeps its checkpoints; `Reporter` tells the web process (and a
progress bar) how it goes.

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
from runs.worker.messages import EpisodeDone, Progress
from study.db.models import (
    Advice,
    Episode,
    Feedback,
    Step,
    StudySession,
    stored_path,
    utcnow,
)
from study.services.advice import AdviceGiven, write_advice
from study.services.feedback import FeedbackGiven, write_feedback

PROGRESS_EVERY_S = 0.2
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
        progress: Callable[[], dict[str, Any]] = dict,
        root: Path | None = None,
    ) -> None:
        """`root`: the storage root the checkpoint paths are stored relative to (None:
        absolute)."""
        self._factory = factory
        self._root = root
        self.session_id = session_id
        self._token = worker_token
        self._dir = checkpoint_dir
        self._flush_every = flush_every_steps
        self._heartbeat_s = heartbeat_s
        self.progress = progress
        """The run's progress, stored with each flush (the `Reporter`'s)."""
        self._steps: list[dict[str, Any]] = []
        self._episodes: list[dict[str, Any]] = []
        self._advice: list[AdviceGiven] = []
        self._feedback: list[FeedbackGiven] = []
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

    def add_feedback(self, feedback: FeedbackGiven) -> None:
        """A machine evaluator's judgement, written at the next flush."""
        self._feedback.append(feedback)

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
            write_feedback(db, self._feedback)
            self._own(db, heartbeat_at=utcnow(), progress=self.progress(), **session_values)
            db.commit()
        self._steps, self._episodes, self._advice, self._feedback = [], [], [], []
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
                checkpoint_path=stored_path(path, self._root),
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
        past its global step, machine advice (or judgements) past its advice count."""
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
                db.execute(
                    delete(Feedback).where(
                        Feedback.session_id == sid, Feedback.feedback_index >= self.advice
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


class Sender(Protocol):
    def send(self, message: Any) -> None: ...


class Reporter:
    """The trainer's callback that tells the web process how the run goes: its `Progress` a
    few times a second and after each training episode, each episode's record; and a
    command line's bar. The run sets what only it knows: `queued`, `waiting_for_participant`,
    and the `advisor` once made (its `count` is the advice given)."""

    def __init__(
        self,
        link: Sender | None,
        recorder: Recorder,
        env: Any,
        episodes: int,
        advice_budget: int,
    ) -> None:
        self.link = link
        """None: nobody listens (a batch run, or the web process is gone)."""
        self.recorder = recorder
        self.env = env
        """The environment the trainer steps (its reward so far; its episode is set here)."""
        self.episodes = episodes
        self.advice_budget = advice_budget
        self.advisor: Any = None
        self.bar: Any = None
        self.stage = "pretrain"
        self.epsilon = 1.0
        self.last_episode_reward: float | None = None
        self.queued = False
        self.waiting_for_participant = False
        self._sent = 0.0
        recorder.progress = self.progress_dict

    @property
    def advice_given(self) -> int:
        return int(getattr(self.advisor, "count", 0))

    def progress(self) -> Progress:
        return Progress(
            stage=self.stage,
            global_step=self.recorder.steps,
            episode=self.recorder.episodes,
            episodes=self.episodes,
            epsilon=self.epsilon,
            collected_reward=self.env.collected_reward,
            last_episode_reward=self.last_episode_reward,
            advice_given=self.advice_given,
            advice_budget=self.advice_budget,
            queued=self.queued,
            waiting_for_participant=self.waiting_for_participant,
        )

    def progress_dict(self) -> dict[str, Any]:
        return vars(self.progress())

    def send(self, message: Any) -> None:
        if self.link is not None:
            self.link.send(message)

    def send_progress(self) -> None:
        self.send(self.progress())
        self._sent = time.monotonic()

    def before_waiting(self) -> None:
        """Before the run blocks on a person or a trainer slot: the live view shows where
        it waits, and every step taken so far is in the database."""
        self.send_progress()
        self.recorder.flush()

    # --- learner callbacks -------------------------------------------------------------
    def on_step(self, record: StepRecord) -> None:
        self.stage = record.stage
        self.epsilon = float(record.epsilon)
        if time.monotonic() - self._sent >= PROGRESS_EVERY_S:
            self.send_progress()

    def on_episode(self, record: EpisodeRecord) -> None:
        self.send(EpisodeDone(record))
        if record.stage != TRAINING:
            return
        self.last_episode_reward = float(record.collected_reward)
        self.env.episode = self.recorder.episodes
        self.send_progress()
        if self.bar is not None:
            self.bar.update(1)
