"""Run a batch to its end: the advisor first when `agent` runs need one, then every run,
a few at a time, with one progress bar for the whole batch.

Re-running the same batch is how it resumes: runs are found by identity
(`runs.batch.sessions`), finished ones are skipped, interrupted ones resume from their
checkpoint, and only the missing ones are created.
"""

from __future__ import annotations

import dataclasses
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import select
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

from learner.advisor_check import AdvisorCheck, checked_advisor, last_check
from learner.fields import FieldError
from learner.run import RunSpec
from runs.batch.backends import NOT_RUN, Backend, LocalBackend, RayBackend, usable_cores
from runs.batch.progress import BatchProgress, MachineShare
from runs.batch.sessions import completed_sources, ensure_session, find_session
from runs.batch.spec import BatchError, BatchSpec, Run, plan_runs, run_spec
from runs.worker.population import default_population, next_group, population_key
from runs.worker.worker import WorkerOptions
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import BACKUPS, upgrade
from study.db.models import (
    ADVISOR_ROLE,
    LIVE_STATUSES,
    RESUMABLE_STATUSES,
    Status,
    StudySession,
    located,
)
from study.services import numerics
from study.services.errors import Invalid
from study.services.ownership import set_status, take_back
from study.services.schedules import write_schedule
from study.services.studies import get_study

TO_RUN = {Status.created.value, *(s.value for s in RESUMABLE_STATUSES)}
LIVE = {s.value for s in LIVE_STATUSES}
WAITING = "waiting for the advisor"
BLOCKED = "not run: the advisor did not finish"
WAITING_PAIR = "waiting for its advised run"
BLOCKED_PAIR = "not run: its advised run did not finish"
REFUSED = "not resumed: its pinned numerics"


@dataclass
class PreviewRow:
    """A run of a dry run (`ideeprl batch --dry-run`) and the session it has."""

    run: str
    method: str
    seed: int
    session: int | None = None
    """Its session's id; None: it has none yet."""
    status: str = "new"
    """Its session's status, or why it has none yet (`new`: it would be created)."""


@dataclass(frozen=True)
class RunnerOptions:
    """How a batch executes (what it runs is the `BatchSpec`)."""

    data_dir: Path = Path("study_data")
    """Checkpoints go to `data_dir/checkpoints/session-ID/` (shared by every node on Ray)."""
    backend: str = "local"
    """`local` (worker processes on this machine) or `ray`."""
    workers: int | None = None
    """Runs at once; None: this machine's cores / the runs' torch threads (local), the
    cluster's (Ray)."""
    address: str | None = None
    """Ray cluster address (`ray://HOST:10001` or `auto`); None starts a local instance."""
    checkpoint_every_episodes: int = 10
    """Training episodes between checkpoints (an interrupted run loses at most these)."""
    heartbeat_s: float = 5.0
    """How often a run marks itself alive (and its progress) in the database."""
    stale_after_s: float = 60.0
    """A run of this batch silent this long (on another host) is taken back and resumed."""
    nice: int = 0
    """Added to each worker's niceness (lower priority beside a live study server)."""
    poll_s: float = 1.0
    """How often the runner looks at its runs."""
    progress: bool = True
    """Show the tqdm bar."""
    override_numerics: bool = False
    """Resume runs whose pinned numerics this machine cannot honour, recording the override;
    without it they are left as they are, with the reason."""
    advisor_check: str = "require"
    """`require`: an advisor checkpoint (given or trained) must pass its check
    (`learner.advisor_check`) before it advises; a trained one that fails is trained again
    from the next seed. `record`: checked and recorded, never refused. `skip`: not checked."""
    advisor_attempts: int = 3
    """Advisors the batch trains at most (seeds advisor_seed, +1, ...) to get one that passes."""
    population: int | None = None
    """Runs trained together in one worker process, at most (`runs.worker.population`),
    among runs that share one learner configuration; None: `default_population`; 1: every
    run alone, in a process of its own."""


@dataclass
class RunState:
    """A run and where its session stands."""

    run: Run
    """Which run."""
    spec: RunSpec
    """The run, derived once from the `BatchSpec` (`run_spec`, checked when the batch was
    made); an `agent` run's advisor checkpoint is added where its session is found or made
    (`BatchRunner._run_spec`), a `procedure` run's schedule once its advised run finished."""
    session_id: int | None = None
    """Its session (None: not created yet, an `agent` run waiting for the advisor)."""
    status: str = WAITING
    """The session's status, or `WAITING` / `BLOCKED`."""
    detail: str = ""
    """Why it failed or stopped."""
    done_before: bool = False
    """It had finished before this invocation."""
    stored: RunSpec | None = None
    """The run as its session stores it (pinned on the machine that made it), read once
    where the session is found or made: its numerics and its population key come from it."""


@dataclass(frozen=True)
class BatchResult:
    """What a batch invocation did."""

    study_id: int
    """The study holding the runs."""
    runs: list[RunState]
    """Every run, the advisor first (when trained)."""
    wall_time_s: float
    """Seconds this invocation took."""
    interrupted: bool
    """Stopped by Ctrl-C (or a signal) before the end."""

    @property
    def complete(self) -> bool:
        return all(r.status == Status.finished.value for r in self.runs)

    def session_ids(self, include_advisor: bool = False) -> list[int]:
        """The runs' sessions, in plan order."""
        return [
            r.session_id
            for r in self.runs
            if r.session_id is not None and (include_advisor or not r.run.is_advisor)
        ]

    @property
    def advisor(self) -> RunState | None:
        return next((r for r in self.runs if r.run.is_advisor), None)


def absolute_database_url(url: str) -> str:
    """SQLite paths made absolute, so worker processes (Ray's included) find the file."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite" and parsed.database not in (None, "", ":memory:"):
        return parsed.set(database=str(Path(parsed.database).resolve())).render_as_string(
            hide_password=False
        )
    return url


class BatchRunner:
    def __init__(
        self,
        spec: BatchSpec,
        study_id: int,
        database_url: str,
        options: RunnerOptions,
        migrate: bool = True,
    ):
        self.spec = spec
        self.study_id = study_id
        self.options = options
        self.database_url = absolute_database_url(database_url)
        engine = make_engine(self.database_url)
        if migrate:
            upgrade(engine, options.data_dir / BACKUPS)
        self.factory: sessionmaker[Session] = make_session_factory(engine)
        if spec.replay_study is not None:
            with self.factory() as db:
                get_study(db, spec.replay_study)
                feedback = spec.spec_of("replayed", spec.template.seed).feedback
                sources = completed_sources(db, spec.replay_study, spec.replay_methods, feedback)
            if not sources:
                raise BatchError(
                    f"study {spec.replay_study} has no finished session of method "
                    f"{' or '.join(spec.replay_methods)} with {feedback} feedback to replay"
                )
            self.spec = spec = dataclasses.replace(spec, replay_sources=tuple(sources))
        self.states = [
            RunState(
                run,
                run_spec(spec, run, None),
                status=WAITING_PAIR if run.method == "procedure" else WAITING,
            )
            for run in plan_runs(spec)
        ]
        given = spec.template.advisor_checkpoint
        self.advisor_checkpoint: str | None = str(Path(given).resolve()) if given else None
        self.advisor_checks: list[tuple[str, AdvisorCheck]] = []
        """Every advisor checkpoint checked by this batch, in order, with its check."""
        self.queue: list[RunState] = []
        self.elsewhere: list[RunState] = []
        self.log: Callable[[str], None] = print

    # --- the runs' sessions ------------------------------------------------------------
    def _retry(self, run: Run) -> RunState:
        """The state of an advisor trained again (a seed after one that failed its check)."""
        return RunState(run, run_spec(self.spec, run, None))

    @staticmethod
    def _run_spec(state: RunState, checkpoint: str | None) -> RunSpec:
        """The run's `RunSpec`, with `checkpoint` advising an `agent` run."""
        if state.run.method != "agent" or checkpoint is None:
            return state.spec
        return state.spec.replace(advisor_checkpoint=checkpoint)

    def _ensure(self, db: Session, state: RunState) -> None:
        spec = self._run_spec(state, self.advisor_checkpoint)
        label = f"{self.spec.label} advisor" if state.run.is_advisor else self.spec.label
        try:
            session, _ = ensure_session(db, self.study_id, spec, label, state.run.source)
        except Invalid as error:
            raise BatchError(error.message) from None
        except FieldError as error:
            raise BatchError(str(error)) from None
        if state.run.is_advisor and session.role != ADVISOR_ROLE:
            session.role = ADVISOR_ROLE  # every attempt: never one of a report's agents
            db.commit()
        state.session_id, state.status = session.id, session.status
        state.done_before = session.status == Status.finished.value
        state.stored = session.spec
        if session.status in TO_RUN and session.status != Status.created.value:
            problem = numerics.refusal(session, state.stored)
            if problem and not self.options.override_numerics:
                state.status, state.detail = REFUSED, problem

    def _advisor_ready(self, db: Session, advisor: RunState) -> bool:
        """The trained advisor's final checkpoint becomes the `agent` runs' advisor once it
        passes its check; when it fails, the next advisor seed is trained (queued here, and
        False returned) until `advisor_attempts` are spent."""
        session = db.get(StudySession, advisor.session_id)
        assert session is not None and session.status == Status.finished.value
        path = located(session.checkpoint_path, self.options.data_dir)
        if not path or not path.is_file():
            raise BatchError(
                f"the advisor (session {session.id}) has finished but its checkpoint "
                f"{path or '(none)'} is gone; pass --advisor-checkpoint, or delete session "
                f"{session.id} to train the advisor again"
            )
        checkpoint = str(path.resolve())
        check = self._check_advisor(checkpoint)
        if check is None or check.passed or self.options.advisor_check == "record":
            self.advisor_checkpoint = checkpoint
            return True
        attempt = advisor.run.seed - self.spec.advisor_seed + 1
        if attempt >= self.options.advisor_attempts:
            raise BatchError(
                f"{attempt} trained advisors failed their check (the last: session "
                f"{session.id}, {'; '.join(check.problems)}); raise --advisor-attempts, give a "
                "checked --advisor-checkpoint, or --advisor-check record to use it anyway"
            )
        self.log(
            f"the advisor of seed {advisor.run.seed} (session {session.id}) failed its check "
            f"({'; '.join(check.problems)}): training the advisor of seed {advisor.run.seed + 1}"
        )
        retry = self._retry(Run("autonomous", -1, advisor.run.seed + 1))
        self.states.insert(self.states.index(advisor) + 1, retry)
        self._ensure(db, retry)
        if retry.status == Status.finished.value:
            return self._advisor_ready(db, retry)
        if retry.status in LIVE:
            self.elsewhere.append(retry)
        else:
            self._enqueue([retry])
        return False

    def _check_advisor(self, checkpoint: str) -> AdvisorCheck | None:
        """`checkpoint` checked for this batch's agent runs (from their advice-time states),
        stored beside it and logged; None when checks are skipped or no agent runs."""
        if self.options.advisor_check == "skip" or "agent" not in self.spec.methods:
            return None
        spec = run_spec(self.spec, Run("agent", 0, self.spec.seed(0)), checkpoint)
        seeds = [self.spec.seed(i) for i in range(self.spec.agents)]
        check = checked_advisor(checkpoint, spec, seeds, allow_failed=True)
        self.advisor_checks.append((checkpoint, check))
        self.log(f"{checkpoint}: {check.summary()}")
        return check

    def _pair_controls(self, db: Session) -> list[RunState]:
        """Create the procedure controls whose advised run (same agent number, method
        `control_of`) has finished, each with that run's schedule; returns them."""
        created = []
        for state in self.states:
            if state.run.method != "procedure" or state.session_id is not None:
                continue
            pair = next(
                (
                    s
                    for s in self.states
                    if s.run.method == self.spec.control_of and s.run.index == state.run.index
                ),
                None,
            )
            if pair is None or pair.session_id is None or pair.status != Status.finished.value:
                continue
            row = db.get(StudySession, pair.session_id)
            assert row is not None
            path = write_schedule(db, row, self.options.data_dir / "schedules")
            state.spec = state.spec.replace(schedule=str(path))
            self._ensure(db, state)
            created.append(state)
        return created

    def _start_controls(self, db: Session) -> None:
        created = self._pair_controls(db)
        self._enqueue([s for s in created if s.status in TO_RUN])
        self.elsewhere += [s for s in created if s.status in LIVE]

    def _create_agent_runs(self, db: Session) -> list[RunState]:
        waiting = [s for s in self.states if s.status == WAITING]
        for state in waiting:
            self._ensure(db, state)
        return waiting

    def preview_rows(self) -> list[PreviewRow]:
        """Each run and the session it has (nothing is created or run)."""
        rows = []
        checkpoint = self.advisor_checkpoint
        with self.factory() as db:
            get_study(db, self.study_id)
            for state in self.states:
                run = state.run
                row = PreviewRow(run.name, run.method, run.seed)
                rows.append(row)
                if run.method == "agent" and checkpoint is None:
                    row.status = "waits for the advisor"
                    continue
                if run.method == "procedure":
                    row.status = f"follows {self.spec.control_of} #{run.index + 1} once it ran"
                    continue
                found = find_session(
                    db, self.study_id, self._run_spec(state, checkpoint), run.source
                )
                if found is not None:
                    row.session, row.status = found.id, found.status
                if run.is_advisor and found is not None and found.status == Status.finished:
                    checkpoint = self._preview_advisor(db, state, found, rows)
        return rows

    def _preview_advisor(
        self, db: Session, state: RunState, found: StudySession, rows: list[PreviewRow]
    ) -> str | None:
        """The checkpoint that would advise, from this finished advisor or the attempts
        after it (each attempt's stored check said in its row); None: none would yet."""
        while True:
            row = rows[-1]
            path = located(found.checkpoint_path, self.options.data_dir)
            check = last_check(path) if path else None
            failed = check is not None and not check.passed
            if failed:
                assert check is not None
                row.status += f"; failed its check ({'; '.join(check.problems)})"
            if not failed or self.options.advisor_check != "require":
                return str(path) if path else None
            attempt = state.run.seed - self.spec.advisor_seed + 1
            if attempt >= self.options.advisor_attempts:
                row.status += f"; {attempt} attempts failed: the batch stops here"
                return None
            state = self._retry(Run("autonomous", -1, state.run.seed + 1))
            next_row = PreviewRow(f"advisor (attempt {attempt + 1})", "autonomous", state.run.seed)
            rows.append(next_row)
            retry = find_session(db, self.study_id, self._run_spec(state, None), None)
            if retry is None:
                return None
            next_row.session, next_row.status = retry.id, retry.status
            if retry.status != Status.finished:
                return None
            found = retry

    def prepare(self) -> None:
        """Find or create every run's session; take back the ones whose worker died. (Every
        run was checked when the `BatchSpec` was made, before anything is written.)"""
        given = self.spec.template.advisor_checkpoint
        if given and self.advisor_checkpoint:
            check = self._check_advisor(self.advisor_checkpoint)
            if check is not None and not check.passed and self.options.advisor_check == "require":
                raise BatchError(
                    f"the advisor {given} failed its check ({'; '.join(check.problems)}); give "
                    "another, or --advisor-check record to use it anyway"
                )
        with self.factory() as db:
            get_study(db, self.study_id)
            for state in list(self.states):
                if state.run.method == "agent" and self.advisor_checkpoint is None:
                    continue  # created once the advisor has finished
                if state.run.method == "procedure":
                    continue  # created once its advised run has finished
                if state.session_id is None:
                    self._ensure(db, state)
                if state.run.is_advisor and state.status == Status.finished.value:
                    self._advisor_ready(db, state)
            self._pair_controls(db)
            live = [s.session_id for s in self.states if s.status in LIVE and s.session_id]
            for session_id in take_back(db, live, self.options.stale_after_s):
                self._state(session_id).status = Status.interrupted.value
        self.queue = [s for s in self.states if s.status in TO_RUN]
        self.elsewhere = [s for s in self.states if s.status in LIVE]

    def _enqueue(self, states: list[RunState]) -> None:
        """Runs wait in plan order (agent by agent), so a batch cut short, or read while it
        runs, has its methods' runs in pairs rather than one method's all first."""
        order = {id(s): i for i, s in enumerate(self.states)}
        self.queue = sorted(self.queue + states, key=lambda s: order[id(s)])

    def _state(self, session_id: int) -> RunState:
        return next(s for s in self.states if s.session_id == session_id)

    def _refresh(self, db: Session) -> dict[int, StudySession]:
        ids = [s.session_id for s in self.states if s.session_id is not None]
        rows = {s.id: s for s in db.scalars(select(StudySession).where(StudySession.id.in_(ids)))}
        for state in self.states:
            if state.session_id in rows:
                row = rows[state.session_id]
                state.status, state.detail = row.status, row.status_detail
        return rows

    # --- running -----------------------------------------------------------------------
    @property
    def threads(self) -> int:
        """Torch threads of each run, as the runs are pinned on this machine."""
        return self.spec.template.pinned().config.torch_threads

    @property
    def population(self) -> int:
        """Runs trained together at most (`RunnerOptions.population`, or the default rule)."""
        if self.options.population is not None:
            return self.options.population
        return default_population(self.spec.template.pinned(), workers=self.options.workers)

    def _next_group(self, workers: int) -> list[RunState]:
        """The next population to start, taken off the queue (`next_group`). An advisor
        that `agent` runs wait for trains alone: it is the batch's critical path."""
        first = self.queue[0]
        waited_for = first.run.is_advisor and any(s.status == WAITING for s in self.states)
        population = 1 if waited_for else self.population
        # a queued run's session was found or made (`_ensure`), so its stored run was read
        keys = [population_key(s.stored) for s in self.queue]  # type: ignore[arg-type]
        group = next_group(self.queue, keys, population, workers)
        taken = {id(s) for s in group}
        self.queue = [s for s in self.queue if id(s) not in taken]
        return group

    def make_backend(self) -> Backend:
        threads = self.threads
        worker = WorkerOptions(
            data_dir=self.options.data_dir.resolve(),
            checkpoint_every_episodes=self.options.checkpoint_every_episodes,
            heartbeat_s=self.options.heartbeat_s,
            nice=self.options.nice,
            override_numerics=self.options.override_numerics,
        )
        if self.options.backend == "ray":
            return RayBackend(
                self.database_url, worker, self.options.address, self.options.workers, threads
            )
        if self.options.backend != "local":
            raise BatchError(f"unknown backend {self.options.backend!r}; use local or ray")
        workers = self.options.workers or max(1, usable_cores() // threads)
        return LocalBackend(self.database_url, worker, workers)

    def _ended(self, db: Session, backend: Backend) -> None:
        ended = backend.ended()
        if not ended:
            return
        rows = self._refresh(db)
        for session_id, problem in ended.items():
            state = self._state(session_id)
            if problem.startswith(NOT_RUN) and state.status in LIVE:
                self.elsewhere.append(state)  # someone else claimed it first: watch it
                continue
            if state.status in LIVE:  # the worker died without saying so (killed, crashed)
                row = rows[session_id]
                set_interrupted(db, row, problem or "its worker stopped without finishing")
                state.status, state.detail = Status.interrupted.value, problem
            if state.run.is_advisor:
                self._after_advisor(db, state)
        self._start_controls(db)

    def _after_advisor(self, db: Session, advisor: RunState) -> None:
        if advisor.status == Status.finished.value:
            if not self._advisor_ready(db, advisor):
                return  # the next advisor seed trains
            created = self._create_agent_runs(db)
            fresh = [s for s in created if s.status in TO_RUN]
            self._enqueue(fresh)
            self.elsewhere += [s for s in created if s.status in LIVE]
        else:
            for state in self.states:
                if state.status == WAITING:
                    state.status = BLOCKED

    def _watch_elsewhere(self, db: Session) -> None:
        """Runs another process was running when we started: wait for them; take them
        back (and run them here) once their worker is gone."""
        if not self.elsewhere:
            return
        self._refresh(db)
        ids = [s.session_id for s in self.elsewhere if s.status in LIVE]
        for session_id in take_back(db, ids, self.options.stale_after_s):  # type: ignore[arg-type]
            state = self._state(session_id)
            state.status = Status.interrupted.value
            self._enqueue([state])
        for state in [s for s in self.elsewhere if s.status not in LIVE]:
            self.elsewhere.remove(state)
            if state.run.is_advisor:
                self._after_advisor(db, state)
        self._start_controls(db)

    def run(self) -> BatchResult:
        started = time.monotonic()
        self.prepare()
        self._announce()
        interrupted = False
        pending = bool(self.queue or self.elsewhere)
        if pending:
            self._announce_populations()
        backend = self.make_backend() if pending else None
        share = (
            MachineShare(usable_cores(), self.threads) if self.options.backend == "local" else None
        )
        bar = BatchProgress(self.states, self.options.progress, share)
        previous = _stop_on_sigterm()
        try:
            while backend is not None:
                busy = backend.busy()  # these workers will take a share when they free
                while self.queue and backend.busy() < backend.capacity:
                    free = backend.capacity - backend.busy()
                    group = self._next_group(free + busy)
                    backend.start(tuple(s.session_id for s in group))  # type: ignore[misc]
                    for state in group:
                        state.status = Status.running.value
                with self.factory() as db:
                    self._ended(db, backend)
                    self._watch_elsewhere(db)
                    rows = self._refresh(db)
                bar.update(rows)
                if not (self.queue or self.elsewhere or backend.running()):
                    break
                time.sleep(self.options.poll_s)
        except KeyboardInterrupt:
            interrupted = True
            bar.write("stopping: the running runs checkpoint and can resume ...")
            assert backend is not None
            running = backend.running()
            backend.stop()
            with self.factory() as db:
                take_back(db, running, 0.0)
                bar.update(self._refresh(db))
        finally:
            for state in self.states:
                if state.status == WAITING_PAIR and not interrupted:
                    state.status = BLOCKED_PAIR
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)
            bar.close()
            if backend is not None:
                backend.close()
        return BatchResult(self.study_id, self.states, time.monotonic() - started, interrupted)

    def _announce_populations(self) -> None:
        size = self.population
        if size > 1:
            how = "as asked" if self.options.population else "the default here"
            self.log(
                f"populations: up to {size} runs of one learner configuration train together "
                f"in each worker ({how}; --population 1 runs each alone)"
            )

    def _announce(self) -> None:
        counts: dict[str, int] = {}
        for state in self.states:
            key = (
                "finished already"
                if state.done_before
                else "to resume"
                if state.status in {s.value for s in RESUMABLE_STATUSES}
                else "running elsewhere"
                if state.status in LIVE
                else "to start"
            )
            counts[key] = counts.get(key, 0) + 1
        methods = ", ".join(
            f"{sum(s.run.method == m and not s.run.is_advisor for s in self.states)} {m}"
            for m in self.spec.methods
        )
        advisor = " and the advisor" if self.spec.trains_advisor else ""
        parts = ", ".join(f"{n} {k}" for k, n in counts.items())
        self.log(
            f"study {self.study_id}, batch {self.spec.label!r}: {len(self.states)} runs "
            f"({methods}{advisor}): {parts}"
        )
        for state in self.states:
            if state.status == Status.failed.value:
                self.log(
                    f"  {state.run.name} seed {state.run.seed}: session {state.session_id} "
                    "failed before; it resumes from its last checkpoint"
                )


def _stop_on_sigterm() -> Any:
    """SIGTERM stops the batch like Ctrl-C (running runs checkpoint); returns the handler
    it replaced, None when signals cannot be handled here (not the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def stop(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, stop)


def set_interrupted(db: Session, row: StudySession, detail: str) -> None:
    set_status(db, row.id, Status.interrupted, detail, token=row.worker_token)


def run_batch(
    spec: BatchSpec, study_id: int, database_url: str, options: RunnerOptions | None = None
) -> BatchResult:
    """Run every missing run of `spec` in the study; see the module docstring."""
    return BatchRunner(spec, study_id, database_url, options or RunnerOptions()).run()


def describe(result: BatchResult) -> list[str]:
    """Lines for the end of a batch: what ran, what did not and why."""
    lines = []
    by_status: dict[str, list[RunState]] = {}
    for state in result.runs:
        by_status.setdefault(state.status, []).append(state)
    for status, states in by_status.items():
        ids = ", ".join(str(s.session_id) for s in states if s.session_id is not None)
        lines.append(f"{len(states)} {status}" + (f" (sessions {ids})" if ids else ""))
    for state in result.runs:
        if state.status == Status.failed.value:
            last = state.detail.strip().splitlines()[-1:] or ["(no detail)"]
            lines.append(f"  {state.run.name} seed {state.run.seed}: {last[0]}")
    return lines
