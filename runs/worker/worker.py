"""One session's run, in the process that owns its environment and learner.

The web process starts `worker_main` in a process per running session, the batch runner
(`runs.batch`) `run_session` in its own processes or Ray tasks; the processes are forked
from a fork server that has loaded torch, PyBullet and the learner once (`worker_context`:
spawning imported them again in every process, about 3 s of CPU each; a worker sees the
environment variables as they were when its process's fork server started). Either
way the worker claims the session, resumes from its last checkpoint when there is one,
logs every record, checkpoints every few episodes and at pause/stop, and writes its own
final status.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import multiprocessing
import os
import socket
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from learner import provenance
from learner.advisors import RecordedAdvisor
from learner.evaluators import RecordedEvaluator
from learner.run import RunSpec, declare, declared
from runs.worker.advisors import Correct, HumanAdvisor, RecordingAdvisor, RecordingEvaluator
from runs.worker.link import HandOver, ParentGone, TaggedChannel, WorkerExit, WorkerLink
from runs.worker.messages import StatusChanged, TrainingWanted
from runs.worker.priority import lower_priority
from runs.worker.rating import HumanEvaluator, given_ratings
from runs.worker.recorder import Checkpointable, LeaseLost, Recorder, Reporter
from runs.worker.scene import SceneBroadcast
from study.db.engine import make_engine, make_session_factory
from study.db.models import Advice, Status, StudySession, located, utcnow
from study.services import numerics
from study.services.errors import Conflict
from study.services.sessions import claim, get_session, set_status

log = logging.getLogger(__name__)

WORKER_PRELOAD = ("torch", "pybullet", "learner.trainer", "sim.env", "runs.worker.worker")
"""What every session worker imports, loaded once in the fork server: `import torch` alone
leaves about 140 MB of private memory in a process; forked from a server that holds it,
the workers share those pages (copy on write) instead of each making its own."""


def worker_context(
    preload: Sequence[str] = WORKER_PRELOAD,
) -> multiprocessing.context.ForkServerContext | multiprocessing.context.SpawnContext:
    """Workers forked from a fork server that has loaded `preload` (a clean single-threaded
    process started for the purpose, never the caller with its threads), or spawned where
    the platform has no fork server. Each worker still owns its PyBullet client, torch
    threads and everything it makes after the fork. One fork server serves a process: the
    first of its workers to start decides what it has loaded (the rest import what it
    lacks)."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(preload))
    return context


@dataclass(frozen=True)
class WorkerOptions:
    """How a worker runs; the server fills it from its settings."""

    data_dir: Path = Path("study_data")
    """Checkpoints go to `data_dir/checkpoints/session-ID/`."""
    shared_storage: bool = False
    """`data_dir` is the storage root of a Ray cluster, which each node may mount under a
    path of its own: checkpoint paths are stored relative to it
    (`study.db.models.stored_path`)."""
    checkpoint_every_episodes: int = 10
    """Training episodes between periodic checkpoints."""
    flush_every_steps: int = 500
    """Step records buffered before a batched insert."""
    heartbeat_s: float = 5.0
    """Longest time between two writes that mark the worker alive."""
    idle_limit_s: float = 1800.0
    """Default idle limit of human sessions (a session's own limit wins)."""
    declaration: type[RunSpec] = field(default_factory=declared)
    """The run's declaration where the worker was started (`learner.run.declared`): a
    worker in a process of its own reads its session's run with it (so a class that
    extends `RunSpec` must be importable there)."""
    override_numerics: bool = False
    """Resume a run whose pinned numerics this machine cannot honour, on what it can, and
    record the override in the session (`numerics_overrides`); without it such a resume is
    refused (`numerics.refusal`)."""
    progress_bar: bool = False
    """Show a tqdm bar of training episodes (command line runs)."""
    nice: int = 0
    """Added to the process's niceness (the server lowers machine sessions' priority)."""
    idle: bool = False
    """Also run in SCHED_IDLE (Linux): only when no ordinary task wants the CPU."""
    keep_replay_memory: bool = False
    """Keep the replay memory in final checkpoints (a session's own choice wins)."""
    pooled: bool = False
    """The session waits in its condition's pool: it practises, then waits for an arrival
    without the idle limit running until one takes it (`Command("assigned")`)."""
    train_nice: int = 0
    """Added to a human session's niceness once its advice is over and it trains alone, so
    the participants still advising keep the CPU."""
    train_idle: bool = False
    """And SCHED_IDLE then (Linux), as `idle`."""
    practice_only: bool = False
    """Run the random practice only: at the step boundary before the earliest step its
    feedback may be asked at (`RunSpec.steps_before_first_turn`), checkpoint and exit,
    still `running` under its token. A pool's practice on a cluster node, whose advice goes
    on next to the web process from that checkpoint (`server.live.cluster`)."""


class _Run:
    def __init__(
        self,
        session_id: int,
        database_url: str,
        options: WorkerOptions,
        token: str,
        conn: Connection | TaggedChannel | None,
        spec: RunSpec | None = None,
    ) -> None:
        """`conn`: the channel to the web process (a `TaggedChannel` for a session in a
        population, whose commands its population's link reads); `spec`: the session's run
        when this process has read it already (its claim settles the numerics)."""
        self.session_id, self.options, self.token = session_id, options, token
        self.factory = make_session_factory(make_engine(database_url))
        with self.factory() as db:
            self.session = get_session(db, session_id)
            self.spec = spec if spec is not None else self.session.spec
            """The session's run, read once in this process."""
            self.given = {  # a person's advice always has its action (only replays lack one)
                a.advice_index: a.action
                for a in db.scalars(select(Advice).where(Advice.session_id == session_id))
                if self.session.method == "human" and a.action is not None
            }
            here = {  # where the run is computed from here on (the report audits it)
                **provenance.record(self.spec.config),
                "at": utcnow().isoformat(),
                "from_step": self.session.checkpoint_step,
                "host": socket.gethostname(),
                "pid": os.getpid(),  # the process (`worker_pid` is cleared when it ends)
            }
            db.execute(
                update(StudySession)
                .where(StudySession.id == session_id, StudySession.worker_token == token)
                .values(
                    worker_pid=os.getpid(),
                    heartbeat_at=utcnow(),
                    provenance=[*self.session.provenance, here],
                )
            )
            db.commit()
        s = self.session
        self.recorder = Recorder(
            self.factory,
            session_id,
            token,
            options.data_dir / "checkpoints" / f"session-{session_id}",
            options.flush_every_steps,
            options.heartbeat_s,
            root=options.data_dir if options.shared_storage else None,
        )
        self.link = (
            WorkerLink(
                conn,
                self._on_pause,
                self._on_watch,
                self.recorder.tick,  # a wait flushes and marks the worker alive
                assigned=not options.pooled,
            )
            if conn
            else None
        )
        checkpoint = located(s.checkpoint_path, options.data_dir)
        if checkpoint and not checkpoint.is_file():
            checkpoint = None  # a fresh start, as for a session never checkpointed
        self.start_advice = s.checkpoint_advice if checkpoint else 0
        self.advisor: Any = None
        if s.method == "human" and self.link is None:
            raise Conflict("a human session needs the server: start it through the API")
        self.advice_budget = self.spec.advice_budget
        """Read once, before the advisor that counts against it is made."""
        self.evaluative = self.spec.feedback == "evaluative"
        """Its feedback judges the learner's own moves (else it advises them)."""
        self.person_rates = s.method == "human" and self.evaluative
        """The participant rates the learner's moves instead of advising."""
        self.live_view = self.spec.the_task.live_view
        """Whether the task has the live 3-D view (else the page shows its frames)."""
        spec = self.spec.validate()
        if spec.method == "agent" and spec.advisor_checkpoint:  # kept relative to the root
            advisor = located(spec.advisor_checkpoint, options.data_dir)
            spec = spec.replace(advisor_checkpoint=str(advisor))
        # The run's parts, each wrapped here: the worker calls into `learner/`, never back.
        env = self._broadcast(spec.make_env(record_motion=isinstance(conn, Connection)))
        self.reporter = Reporter(
            self.link, self.recorder, env, spec.config.episodes, self.advice_budget
        )
        task, task_options = spec.the_task, spec.env_options()
        self.correct: Correct = functools.partial(task.correct_actions, options=task_options)
        """The task's correct action at a step, stored beside each advice and judgement."""
        advisor = self._advisor(spec.make_advisor())  # None for sb3-dqn, which takes none
        evaluator = self._evaluator(spec.make_evaluator())  # evaluative feedback's, or None
        self.reporter.advisor = self.advisor
        self.trainer = spec.make_trainer(env, advisor, [self.recorder, self.reporter], evaluator)
        if checkpoint:
            self.trainer.load_checkpoint(checkpoint)
        else:
            s.checkpoint_step = s.checkpoint_episodes = s.checkpoint_advice = 0
        self.recorder.rewind(s)
        self.env.steps = self.recorder.steps
        self.env.episode = self.recorder.episodes
        self.reporter.stage = str(getattr(self.trainer, "stage", "pretrain"))
        self.saver: Checkpointable = self.trainer
        """What writes the run's checkpoints: its trainer, or a population's agent (whose
        checkpoint also records the population's numerics)."""

    def _broadcast(self, env: Any) -> SceneBroadcast:
        """The environment as the trainer sees it: each step also goes to the live view."""
        self.env = SceneBroadcast(env, self.link, self.live_view)
        renders = getattr(env, "render_mode", None) == "rgb_array"
        self.frames: Callable[[], Any] | None = (
            self.env.render if renders and not self.live_view else None
        )
        """What people see of a task without a live 3-D view: its environment's rendered
        frame (Gymnasium's `render_mode="rgb_array"`), or None where it renders none."""
        return self.env

    def _advisor(self, machine: Any) -> Any:
        """The session's advisor: a person through the web process (human), or the machine
        advisor with its advice recorded."""
        s = self.session
        if self.evaluative:
            return None  # `_evaluator` makes the person's, or the recorded ratings' evaluator
        if s.method == "human":
            assert self.link is not None
            self.advisor = HumanAdvisor(
                self.link,
                self.reporter,
                self.given,
                self.start_advice,
                self.advice_budget,
                s.idle_limit_s or self.options.idle_limit_s,
                frames=self.frames,
                correct=self.correct,
            )
            self.env.after_step.append(self.advisor.after_step)
            self.env.participant = self.advisor
        elif s.method == "replayed":
            stream = s.replay_stream
            if not stream:
                raise Conflict(
                    f"session {s.id} is a replay without its recorded stream: make replays "
                    "with `ideeprl replay`"
                )
            self.advisor = RecordingAdvisor(
                RecordedAdvisor(stream["actions"], stream["observation_hashes"]),
                s.id,
                s.method,
                self.start_advice,
                self.recorder,
                self.correct,
                self.frames,
            )
        elif machine is not None:
            self.advisor = RecordingAdvisor(
                machine, s.id, s.method, self.start_advice, self.recorder, self.correct,
                self.frames,
            )  # fmt: skip
        return self.advisor

    def _evaluator(self, machine: Any) -> RecordingEvaluator | HumanEvaluator | None:
        """Under evaluative feedback, the machine evaluator with its judgements recorded;
        it stands as the session's advisor (its count is the feedback given)."""
        if self.person_rates:
            return self._person_rates()
        if self.evaluative and self.session.method == "replayed":
            machine = self._recorded_ratings()
        if machine is None:
            return None
        s = self.session
        self.advisor = RecordingEvaluator(
            machine, s.id, s.method, self.start_advice, self.spec.feedback_weight, self.recorder,
            self.correct,
        )  # fmt: skip
        return self.advisor

    def _recorded_ratings(self) -> RecordedEvaluator:
        """A replay's stream of ratings, fed by order."""
        s = self.session
        stream = s.replay_stream
        if not stream or "judgements" not in stream:
            raise Conflict(
                f"session {s.id} is a replay of ratings without its recorded stream: make "
                "replays with `ideeprl replay`"
            )
        return RecordedEvaluator(stream["judgements"], stream["observation_hashes"])

    def _person_rates(self) -> HumanEvaluator:
        """Evaluative feedback from the participant, on the advice page."""
        assert self.link is not None
        evaluator = HumanEvaluator(
            self.link,
            self.reporter,
            given_ratings(self.factory, self.session_id),
            self.start_advice,
            self.advice_budget,
            self.session.idle_limit_s or self.options.idle_limit_s,
            self.spec.rating_time_out_s,
            frames=self.frames,
            correct=self.correct,
        )
        self.env.after_step.append(evaluator.after_step)
        self.env.participant = evaluator
        self.advisor = evaluator
        return evaluator

    @property
    def advice_given(self) -> int:
        return self.reporter.advice_given

    def send(self, message: Any) -> None:
        self.reporter.send(message)

    def send_progress(self) -> None:
        self.reporter.send_progress()

    def set_status(self, status: Status, detail: str = "") -> None:
        with self.factory() as db:
            if not set_status(db, self.session_id, status, detail, token=self.token):
                raise LeaseLost(f"session {self.session_id} is no longer this worker's")
        self.send(StatusChanged(status.value, detail))

    def checkpoint(self, name: str = "") -> None:
        self.recorder.checkpoint(self.saver, self.advice_given, name)

    def _on_pause(self, paused: bool, at_step_boundary: bool) -> None:
        if paused and at_step_boundary:
            self.checkpoint()
        self.send_progress()
        with self.factory() as db:
            set_status(
                db, self.session_id, Status.paused if paused else Status.running, token=self.token
            )

    def _on_watch(self) -> None:
        self.env.announce()

    def _needs_training_slot(self) -> bool:
        """A human session whose advice is over trains only in one of the server's slots."""
        return (
            self.link is not None
            and self.session.method == "human"
            and not self.link.may_train
            and self.advice_given >= self.advice_budget
        )

    def _wait_for_training_slot(self) -> None:
        assert self.link is not None
        self.reporter.queued = True
        self.send(TrainingWanted())
        self.reporter.before_waiting()
        self.link.wait_for_training_slot()
        self.reporter.queued = False
        if self.options.train_nice:
            lower_priority(self.options.train_nice, idle=self.options.train_idle)
        self.send_progress()

    def run(self) -> Status:
        self.send(StatusChanged(Status.running.value))
        self.send_progress()
        if self.options.progress_bar:
            from tqdm import tqdm

            self.reporter.bar = tqdm(
                total=self.spec.config.episodes,
                initial=self.recorder.episodes,
                desc=f"session {self.session_id}",
                unit="episode",
            )
        try:
            while not self.trainer.done:
                try:
                    if self.link is not None:
                        self.link.poll()
                    self.between_steps()
                    if self.practised():
                        raise HandOver("practised up to its first turn")
                except WorkerExit as exit_:
                    return self.exit(exit_, at_step_boundary=True)
                try:
                    self.trainer.step()
                except WorkerExit as exit_:
                    return self.exit(exit_, at_step_boundary=False)
            return self.finish()
        finally:
            if self.reporter.bar is not None:
                self.reporter.bar.close()

    def between_steps(self) -> None:
        """What a run does between two learner steps: heartbeat and flush when due, wait for
        a training slot, checkpoint every few episodes (a population's worker calls it for
        each of its agents)."""
        self.recorder.tick()
        if self._needs_training_slot():
            self._wait_for_training_slot()
        if self.recorder.episodes_since_checkpoint >= self.options.checkpoint_every_episodes:
            self.checkpoint()

    def practised(self) -> bool:
        """A practice-only run (`WorkerOptions.practice_only`) has reached its first turn."""
        return self.options.practice_only and self.recorder.steps >= self.first_turn

    @functools.cached_property
    def first_turn(self) -> int:
        """Random practice steps before its earliest feedback."""
        return self.spec.steps_before_first_turn()

    def finish(self) -> Status:
        """The trainer is done: the final checkpoint, then the session is finished."""
        keep = self.session.keep_replay_memory
        keep = self.options.keep_replay_memory if keep is None else keep
        self.recorder.checkpoint(self.saver, self.advice_given, "final.pt", memory=keep)
        self.set_status(Status.finished)
        self.send_progress()
        return Status.finished

    def exit(self, exit_: WorkerExit, at_step_boundary: bool) -> Status:
        if at_step_boundary:
            self.checkpoint()
        else:
            self.recorder.flush()
        status = Status(exit_.status)
        if isinstance(exit_, HandOver):  # still running, under its token: nothing to record
            return status
        if isinstance(exit_, ParentGone):
            self.link = self.reporter.link = None  # nobody is listening any more
        self.set_status(status, str(exit_))
        return status


def run_session(
    session_id: int,
    database_url: str,
    options: WorkerOptions | None = None,
    *,
    worker_token: str | None = None,
    conn: Connection | None = None,
) -> str:
    """Run one session to its end in this process; returns its final status.

    Without `worker_token` the session is claimed here (created sessions start, stopped or
    interrupted ones resume). Human sessions need `conn`, the channel to the web process."""
    options = options or WorkerOptions()
    if options.nice:
        lower_priority(options.nice, idle=options.idle)
    with declare(options.declaration):
        factory = make_session_factory(make_engine(database_url))
        spec = None
        if worker_token is None:
            worker_token, spec = claim_session(factory, session_id, options, human=conn is not None)
        try:
            run = _Run(session_id, database_url, options, worker_token, conn, spec)
            return run.run().value
        except LeaseLost as error:
            log.warning("%s", error)
            return "lost"
        except Exception as error:
            fail_session(factory, session_id, worker_token, error, conn)
            return Status.failed.value


def claim_session(
    factory: sessionmaker[Session], session_id: int, options: WorkerOptions, human: bool = False
) -> tuple[str, RunSpec]:
    """Claim the session for this process (created sessions start, stopped or interrupted
    ones resume), its numerics settled; returns the worker token and the run as this
    machine computes it. `human`: a channel to the web process is there (a human session
    needs one)."""
    with factory() as db:
        session = get_session(db, session_id)
        if session.method == "human" and not human:
            raise Conflict(f"session {session_id} is a human session: start it through the server")
        spec = numerics.settle(db, session, session.spec, options.override_numerics)
        return claim(db, session_id, resume=session.status != Status.created), spec


def fail_session(
    factory: sessionmaker[Session],
    session_id: int,
    token: str,
    error: BaseException,
    conn: Connection | TaggedChannel | None = None,
) -> None:
    """The run raised `error`: the session is failed with its traceback (it resumes from its
    last checkpoint when run again)."""
    detail = "".join(traceback.format_exception(error))
    log.error("session %s failed:\n%s", session_id, detail)
    with factory() as db:
        set_status(db, session_id, Status.failed, detail[-4000:], token=token)
    if conn is not None:
        with contextlib.suppress(OSError):
            conn.send(StatusChanged(Status.failed.value, str(error)))


def worker_main(
    session_id: int,
    database_url: str,
    options: WorkerOptions,
    worker_token: str,
    conn: Connection,
) -> None:
    """Entry point of a spawned worker process."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s worker %(process)d %(message)s")
    run_session(session_id, database_url, options, worker_token=worker_token, conn=conn)
    conn.close()
