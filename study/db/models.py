"""The study database's tables, as SQLAlchemy 2.0 typed models.

One study has many sessions; a session (one learner's run) has its step, episode and
advice (or evaluative feedback) records. Records carry unique (session, index) keys so a
resumed worker can never write a row twice.
"""

from __future__ import annotations

import enum
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, ClassVar

from sqlalchemy import (
    JSON,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
    false,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from learner.run import METHODS, UNADVISED, RunSpec, declared


def utcnow() -> datetime:
    return datetime.now(UTC)


def stored_path(path: Path, root: Path | None) -> str:
    """A checkpoint's path as a session's row keeps it (`StudySession.checkpoint_path`):
    relative to `root`, the storage root a Ray cluster's nodes share (each may mount it
    under a path of its own), when it lies there; absolute with `root` None, as one
    machine's training keeps it."""
    if root is None:
        return str(path)
    absolute, base = Path(path).absolute(), Path(root).absolute()
    return str(absolute.relative_to(base)) if absolute.is_relative_to(base) else str(absolute)


def located(path: str | None, root: Path) -> Path | None:
    """The file a row's checkpoint path names on this machine, whose storage root is mounted
    at `root`: a relative path joined to it, an absolute one (one machine's training, or a
    database written before checkpoint paths were kept relative) as it is; None: no path."""
    if not path:
        return None
    found = Path(path)
    return found if found.is_absolute() else Path(root) / found


class UTCDateTime(TypeDecorator[datetime]):
    """Timestamps in UTC on every backend (SQLite forgets the zone; we put it back)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_result_value(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is not None and value.tzinfo is None:
            return value.replace(tzinfo=UTC)
        return value


class Base(DeclarativeBase):
    type_annotation_map: ClassVar[dict[Any, Any]] = {dict[str, Any]: JSON, list[Any]: JSON}


Method = enum.StrEnum(  # type: ignore[misc]
    "Method", {name.replace("-", "_"): name for name in METHODS}
)
"""A run's method (`learner.run.METHODS`: who advises the learner), as an enum."""

UNADVISED_METHODS = tuple(Method(name) for name in UNADVISED)
"""Methods without an advisor: no strategy, no advice budget."""


class Status(enum.StrEnum):
    """Where a session is in its life; see docs/api.md for the transitions."""

    created = "created"
    running = "running"
    paused = "paused"
    finished = "finished"
    stopped = "stopped"
    interrupted = "interrupted"
    abandoned = "abandoned"
    failed = "failed"
    declined = "declined"
    """An online study's participant declined consent: their visit ended, worker freed."""
    excluded = "excluded"
    """An online study's participant failed the comprehension check."""
    timed_out = "timed_out"
    """An online study's participant gave no answer for the design's idle limit (final)."""


ENDED_EARLY = (Status.declined, Status.excluded, Status.timed_out)
"""Final statuses of a visit that ended before its advice: its place is refilled."""


class Outcome(enum.StrEnum):
    """How a participant's visit ended (`sessions.outcome`); each has its own code and
    redirect in an online study's design. `full` is never stored: an arrival turned away
    gets no session."""

    completed = "completed"
    declined = "declined"
    excluded = "excluded"
    timed_out = "timed_out"
    full = "full"


LIVE_STATUSES = (Status.running, Status.paused)
RESUMABLE_STATUSES = (Status.stopped, Status.interrupted, Status.abandoned, Status.failed)


ADVISOR_ROLE = "advisor"
"""`StudySession.role` of the advisors a batch trains for its `agent` runs."""


class Study(Base):
    __tablename__ = "studies"
    __table_args__ = {"sqlite_autoincrement": True}  # noqa: RUF012 (as SQLAlchemy declares it); ids never return

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    description: Mapped[str] = mapped_column(Text, default="")
    texts: Mapped[dict[str, Any]] = mapped_column(default=dict)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    design: Mapped[dict[str, Any] | None] = mapped_column()
    """An online study's design (`study.schemas.design.StudyDesign`, every default written
    out); None for a lab study, whose sessions are made by hand."""
    join_key: Mapped[str | None] = mapped_column(String(64), unique=True)
    """The unguessable key of the study's public link `/join/{join_key}`."""
    assignment_seed: Mapped[int | None] = mapped_column(Integer)
    sessions_made: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    """Sessions the study's link and pools have made: the next one's number, which its run's
    seed adds to the condition's (never reused, deletions included)."""
    """Seed of the block randomization over the design's conditions."""

    sessions: Mapped[list[StudySession]] = relationship(
        back_populates="study", cascade="all, delete-orphan", passive_deletes=True
    )
    texts_versions: Mapped[list[StudyTexts]] = relationship(
        back_populates="study", cascade="all, delete-orphan", passive_deletes=True
    )
    participants: Mapped[list[Participant]] = relationship(
        back_populates="study", cascade="all, delete-orphan", passive_deletes=True
    )


class StudyTexts(Base):
    """One distinct version of the texts a study's participants read (consent, induction,
    thanks), exactly as shown: placeholders filled in. Rows are never changed: editing a
    study's texts after sessions ran makes a new version, and each session points at the
    version its participant consented (or declined) to."""

    __tablename__ = "study_texts"
    __table_args__ = (
        UniqueConstraint("study_id", "content_hash"),
        UniqueConstraint("study_id", "version"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"))
    version: Mapped[int] = mapped_column(Integer)
    content_hash: Mapped[str] = mapped_column(String(64))
    texts: Mapped[dict[str, Any]] = mapped_column()
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    study: Mapped[Study] = relationship(back_populates="texts_versions")


class Participant(Base):
    """A person who advises, known only by a pseudonym (never a name, never in a path)."""

    __tablename__ = "participants"
    __table_args__ = (UniqueConstraint("study_id", "pseudonym"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"))
    pseudonym: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    study: Mapped[Study] = relationship(back_populates="participants")


class StudySession(Base):
    """One learner's run: its full configuration, its status and where it can resume from."""

    __tablename__ = "sessions"
    __table_args__ = {"sqlite_autoincrement": True}  # noqa: RUF012 (as SQLAlchemy declares it)

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    participant_id: Mapped[int | None] = mapped_column(
        ForeignKey("participants.id", ondelete="SET NULL")
    )
    label: Mapped[str] = mapped_column(String(200), default="")
    run: Mapped[dict[str, Any]] = mapped_column()
    """The run, described once: `learner.run.RunSpec.to_json()` (versioned, every field
    spelled out, numerics pinned when the session was created); `spec` reads it back."""
    provenance: Mapped[list[Any]] = mapped_column(default=list)
    """Where the run was computed, one entry each time a worker started or resumed it
    (`learner.provenance.record`: code version, commit, CPU kind, torch, numerics, and the
    step it started from); empty for a run that never started, or stored before 0009."""
    numerics_overrides: Mapped[list[Any]] = mapped_column(default=list)
    """Resumes that overrode the pinned numerics (each: when, at which step, from what to
    what, and why); empty for a run computed as it was pinned throughout."""
    idle_limit_s: Mapped[float | None] = mapped_column(Float)
    keep_replay_memory: Mapped[bool | None] = mapped_column()
    """Keep the replay memory in the final checkpoint; None: the server's setting."""
    participant_token: Mapped[str | None] = mapped_column(String(100), unique=True)

    status: Mapped[str] = mapped_column(String(20), default=Status.created.value, index=True)
    status_detail: Mapped[str] = mapped_column(Text, default="")
    progress: Mapped[dict[str, Any]] = mapped_column(default=dict)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime())

    worker_token: Mapped[str | None] = mapped_column(String(40))
    worker_pid: Mapped[int | None] = mapped_column(Integer)
    worker_host: Mapped[str | None] = mapped_column(String(255))
    heartbeat_at: Mapped[datetime | None] = mapped_column(UTCDateTime())

    checkpoint_path: Mapped[str | None] = mapped_column(Text)
    """Its last checkpoint: absolute, or relative to the storage root (`located`)."""
    checkpoint_step: Mapped[int] = mapped_column(Integer, default=0)
    checkpoint_episodes: Mapped[int] = mapped_column(Integer, default=0)
    checkpoint_advice: Mapped[int] = mapped_column(Integer, default=0)

    texts_version_id: Mapped[int | None] = mapped_column(
        ForeignKey("study_texts.id", ondelete="SET NULL")
    )
    consented_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    declined_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    induction_done_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    condition: Mapped[str | None] = mapped_column(String(100))
    """The design condition this session was assigned to (None outside an online study)."""
    preview: Mapped[bool] = mapped_column(default=False, server_default=false())
    pooled: Mapped[bool] = mapped_column(default=False, server_default=false())
    """Made ahead of arrivals, its random pretraining done, waiting in its condition's pool
    (no participant yet: not counted, exported or reported until an arrival takes it)."""
    """A researcher's walk through the study link: takes no place, stays out of exports
    and reports."""
    outcome: Mapped[str | None] = mapped_column(String(20))
    """How the participant's visit ended (`Outcome`); None while it goes on."""
    outcome_at: Mapped[datetime | None] = mapped_column(UTCDateTime())

    replay_of: Mapped[int | None] = mapped_column(
        ForeignKey("sessions.id", ondelete="CASCADE"), index=True
    )
    """The session whose advice this one replays (method `replayed`), when it is in this
    database: deleting it (or its participant) deletes this replay too."""
    replay_stream: Mapped[dict[str, Any] | None] = mapped_column()
    """A replay's recorded advice stream, copied when it was made so that it resumes and
    reads the same without its source: `source` (study, session, export file or None),
    `actions` and `observation_hashes` (of the images the advisor saw), in advice order."""
    role: Mapped[str | None] = mapped_column(String(20))
    """`advisor`: trained by a batch as the agent method's advisor (`ADVISOR_ROLE`), each
    attempt, passed its check or not, used or not; never one of a report's compared agents.
    None: any other session."""

    study: Mapped[Study] = relationship(back_populates="sessions")
    participant: Mapped[Participant | None] = relationship()
    texts_version: Mapped[StudyTexts | None] = relationship()

    @property
    def spec(self) -> RunSpec:
        """The run this session describes (`run` read back as the run's declaration,
        `learner.run.declared`, every value checked; fields declared since it was stored
        take their defaults). Read it once and pass the object on."""
        return declared().from_json(self.run)

    @property
    def method(self) -> str:
        """The run's method (who advises), read from `run`."""
        return str(self.run.get("method", ""))

    @property
    def seed(self) -> int:
        """The run's seed, read from `run`."""
        return int(self.run.get("seed", 0))

    @property
    def ready_for_advice(self) -> bool:
        """A person may be asked for advice only after consent and the induction."""
        return self.consented_at is not None and self.induction_done_at is not None


class Step(Base):
    """One environment step: the learner's `StepRecord` (columns documented there)."""

    __tablename__ = "steps"
    __table_args__ = (UniqueConstraint("session_id", "global_step"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"))
    global_step: Mapped[int] = mapped_column(Integer)
    stage: Mapped[str] = mapped_column(String(20))
    episode: Mapped[int] = mapped_column(Integer)
    episode_step: Mapped[int] = mapped_column(Integer)
    action: Mapped[int] = mapped_column(Integer)
    action_source: Mapped[str] = mapped_column(String(20))
    greedy_action: Mapped[int] = mapped_column(Integer)
    q_grab: Mapped[float | None] = mapped_column(Float)
    q_move_right: Mapped[float | None] = mapped_column(Float)
    q_move_left: Mapped[float | None] = mapped_column(Float)
    q_drop: Mapped[float | None] = mapped_column(Float)
    q_values: Mapped[str | None] = mapped_column(Text)
    advised_action: Mapped[int | None] = mapped_column(Integer)
    advice_remaining: Mapped[int] = mapped_column(Integer)
    reward: Mapped[float] = mapped_column(Float)
    terminated: Mapped[bool] = mapped_column()
    truncated: Mapped[bool] = mapped_column()
    outcome: Mapped[str | None] = mapped_column(String(10))
    """`placed`, `misplaced`, `lost` or `none`; NULL (unknown) in rows stored before 0010
    whose episodes were not replayed yet (`study.services.outcomes`)."""
    epsilon: Mapped[float] = mapped_column(Float)
    loss: Mapped[float | None] = mapped_column(Float)
    observation_hash: Mapped[str | None] = mapped_column(String(16))
    """NULL in rows stored before 0012."""
    wall_time: Mapped[float] = mapped_column(Float)


class Episode(Base):
    """One episode, pretraining or training: the learner's `EpisodeRecord`."""

    __tablename__ = "episodes"
    __table_args__ = (UniqueConstraint("session_id", "stage", "episode"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"))
    stage: Mapped[str] = mapped_column(String(20))
    episode: Mapped[int] = mapped_column(Integer)
    collected_reward: Mapped[float] = mapped_column(Float)
    steps: Mapped[int] = mapped_column(Integer)
    placed_correct: Mapped[int] = mapped_column(Integer)
    misplaced: Mapped[int] = mapped_column(Integer)
    lost: Mapped[int] = mapped_column(Integer)
    success: Mapped[bool] = mapped_column()
    terminated: Mapped[bool] = mapped_column()
    truncated: Mapped[bool] = mapped_column()
    advised_steps: Mapped[int] = mapped_column(Integer)
    epsilon: Mapped[float] = mapped_column(Float)
    mean_loss: Mapped[float | None] = mapped_column(Float)
    first_global_step: Mapped[int] = mapped_column(Integer)
    last_global_step: Mapped[int] = mapped_column(Integer)
    wall_time: Mapped[float] = mapped_column(Float)
    reset_seed: Mapped[int | None] = mapped_column(Integer)
    """The environment's reset seed (None for episodes recorded before it was kept)."""


class Advice(Base):
    """One piece of advice: what the advisor saw, chose, and how long it took."""

    __tablename__ = "advice"
    __table_args__ = (
        UniqueConstraint("session_id", "advice_index"),
        Index("ix_advice_session_step", "session_id", "global_step"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"))
    advice_index: Mapped[int] = mapped_column(Integer)
    global_step: Mapped[int] = mapped_column(Integer)
    advisor: Mapped[str] = mapped_column(String(20))
    action: Mapped[int | None] = mapped_column(Integer)
    """The advised action; NULL only for a replay's request beyond its recorded stream (it
    was asked for, counted against the budget, and none was given)."""
    greedy_action: Mapped[int | None] = mapped_column(Integer)
    observation_png: Mapped[bytes] = mapped_column(LargeBinary)
    response_time_s: Mapped[float] = mapped_column(Float)
    decision_time_s: Mapped[float | None] = mapped_column(Float)
    requested_at: Mapped[datetime] = mapped_column(UTCDateTime())
    answered_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    same_observation: Mapped[bool | None] = mapped_column()
    """Replayed advice: whether the replay showed the advice the image its advisor saw
    (equal observation hashes); NULL for advice given live, and for requests beyond the
    stream."""
    correct_action: Mapped[int | None] = mapped_column(Integer)
    """The task's correct action at the advised step (`tasks.Task.correct`), for the advice's
    accuracy; NULL where the task cannot say, and in rows stored before 0018."""
    correct_actions: Mapped[list[Any] | None] = mapped_column(JSON)
    """Every action as right as the correct one at that step, the correct one among them
    (`tasks.Task.correct_actions`: the grid world's moves equally near the goal), for the
    advice's accuracy; NULL where the task cannot say, and in rows stored before 0020 (their
    accuracy reads `correct_action` alone)."""


class Feedback(Base):
    """One judgement of evaluative feedback (`learner.evaluators`): the action the learner
    took by itself, how its evaluator judged it, and what that added to the reward the
    learner remembers."""

    __tablename__ = "feedback"
    __table_args__ = (
        UniqueConstraint("session_id", "feedback_index"),
        Index("ix_feedback_session_step", "session_id", "global_step"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"))
    feedback_index: Mapped[int] = mapped_column(Integer)
    global_step: Mapped[int] = mapped_column(Integer)
    evaluator: Mapped[str] = mapped_column(String(20))
    action: Mapped[int] = mapped_column(Integer)
    """The action judged: the learner's own, the one taken."""
    judgement: Mapped[float | None] = mapped_column(Float)
    """+1 good, -1 bad (or a signed value); NULL: no answer."""
    shaping: Mapped[float] = mapped_column(Float)
    """What the judgement added to the environment's reward (the run's feedback_weight
    times the judgement; 0 without one)."""
    greedy_action: Mapped[int] = mapped_column(Integer)
    observation_hash: Mapped[str] = mapped_column(String(16))
    response_time_s: Mapped[float] = mapped_column(Float)
    decision_time_s: Mapped[float | None] = mapped_column(Float)
    requested_at: Mapped[datetime] = mapped_column(UTCDateTime())
    answered_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    correct_action: Mapped[int | None] = mapped_column(Integer)
    """The task's correct action at the rated step (`tasks.Task.correct`), for the rating's
    accuracy; NULL where the task cannot say, and in rows stored before 0019."""
    correct_actions: Mapped[list[Any] | None] = mapped_column(JSON)
    """Every action as right as the correct one at the rated step, the correct one among
    them, for the rating's accuracy; NULL where the task cannot say, and in rows stored
    before 0020."""


class CheckAttempt(Base):
    """One try at an online study's comprehension check (`study.schemas.visit.CheckSpec`):
    what the participant chose and what was right under their session's sort rule."""

    __tablename__ = "check_attempts"
    __table_args__ = (UniqueConstraint("session_id", "attempt"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"))
    attempt: Mapped[int] = mapped_column(Integer)
    """1 for the first try."""
    answers: Mapped[dict[str, Any]] = mapped_column()
    """{question id: the chosen value}."""
    expected: Mapped[dict[str, Any]] = mapped_column()
    """{question id: the right value}, computed from the session's sort rule at the time."""
    questions: Mapped[dict[str, Any]] = mapped_column()
    """{question id: its text}, exactly as shown."""
    correct: Mapped[bool] = mapped_column()
    answered_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)


class QuestionnaireAnswer(Base):
    """One item of an online study's questionnaire as submitted; an item skipped has no value."""

    __tablename__ = "questionnaire_answers"
    __table_args__ = (UniqueConstraint("session_id", "instrument", "item"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"))
    instrument: Mapped[str] = mapped_column(String(40))
    """`nasa_tlx`, `trust`, `demographics` or `custom` (the researcher's items)."""
    item: Mapped[str] = mapped_column(String(40))
    text: Mapped[str] = mapped_column(Text)
    """The item exactly as shown."""
    value_number: Mapped[float | None] = mapped_column(Float)
    """A Likert point (1..points) or a number; None for choices and text."""
    value_text: Mapped[str | None] = mapped_column(Text)
    """A choice, free text, or "Prefer not to say"."""
    answered_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)


class FittedAdvisorModel(Base):
    """An advisor model fitted to a study's sessions (`learner.fitted.FittedModel`). It is
    made from their participants' advice, so deleting any of those sessions (or their
    participant, or the study) deletes it (`study.services.storage`)."""

    __tablename__ = "fitted_advisors"
    __table_args__ = {"sqlite_autoincrement": True}  # noqa: RUF012 (as SQLAlchemy declares it)

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    model: Mapped[dict[str, Any]] = mapped_column()
    """`FittedModel.to_json()`: versioned, with its rates, times and budget use."""
    session_ids: Mapped[list[Any]] = mapped_column()
    """The sessions whose advice it was fitted from."""


class Assignment(Base):
    """How an arrival at an online study's link was assigned: its condition, and where in
    the block randomization (block, position in it, the study's seed). A refill takes the
    place of a visit that ended early (`refills`: that assignment's id)."""

    __tablename__ = "assignments"
    __table_args__ = {"sqlite_autoincrement": True}  # noqa: RUF012 (as SQLAlchemy declares it)

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    session_id: Mapped[int] = mapped_column(
        ForeignKey("sessions.id", ondelete="CASCADE"), unique=True
    )
    condition: Mapped[str] = mapped_column(String(100))
    block: Mapped[int] = mapped_column(Integer)
    position: Mapped[int] = mapped_column(Integer)
    seed: Mapped[int] = mapped_column(Integer)
    refills: Mapped[int | None] = mapped_column(Integer)
    assigned_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)


class PanelId(Base):
    """A participant's ids at their panel (Prolific's, MTurk's), kept apart from the
    sessions: only payment needs them, and deleting them by panel id deletes the person's
    sessions too. `panel_id` names the person (the design's first panel parameter)."""

    __tablename__ = "panel_ids"
    __table_args__ = (UniqueConstraint("study_id", "panel_id"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"))
    participant_id: Mapped[int] = mapped_column(
        ForeignKey("participants.id", ondelete="CASCADE"), unique=True
    )
    panel_id: Mapped[str] = mapped_column(String(200))
    params: Mapped[dict[str, Any]] = mapped_column()
    """Every panel parameter of the arrival (submission and study ids)."""
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
