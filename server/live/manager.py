"""The web process's side of the running sessions: starts worker processes, talks to them
over their pipes, publishes what they say on the hub, and notices when one dies.

State that the participant endpoints read (the pending advice request, whether the robot
moves, recent history) lives on a `WorkerHandle` and changes only on the event loop's
thread; each pipe has a reader thread that publishes to the hub and hands messages over.

A human session asks for advice only once its participant is ready (consent and induction
recorded; the manager then sends `Command("ready")`), and trains after its advice only in
one of `max_trainers` slots: the others wait in a queue (`queued`), so the people still
advising never share the cores with more trainers than there are cores. A slot that frees
takes the session queued longest together with the queued sessions that can train with it
(one learner configuration, up to `training_population`), by the batch's rule
(`runs.worker.population.next_group`): one alone trains on in its own worker; several
are handed over (`Command("handover")`: each worker checkpoints and exits, the session
still `running` under its token) to one population worker (`population_main`), which
sends each session's messages `Tagged` with it, so each keeps its own handle, progress,
records, checkpoints and status.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import multiprocessing
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import datetime
from multiprocessing import forkserver
from multiprocessing.connection import Connection
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from learner.run import RunSpec
from learner.strategies import make_strategy
from runs.worker.link import SHUTTING_DOWN, WAITED_FOR_PARTICIPANT
from runs.worker.messages import (
    AdviceRequest,
    AdviceResult,
    Command,
    EpisodeDone,
    Progress,
    SceneReset,
    SceneStep,
    StatusChanged,
    Tagged,
    TrainingWanted,
)
from runs.worker.population import (
    default_population,
    next_group,
    population_key,
    population_main,
)
from runs.worker.worker import WorkerOptions, worker_main
from server.live import visits
from server.live.cluster import TrainingCluster
from server.live.hub import Hub
from server.live.reaping import join
from study.db.models import (
    LIVE_STATUSES,
    RESUMABLE_STATUSES,
    Advice,
    Status,
    StudySession,
    utcnow,
)
from study.services import numerics
from study.services.assignment import expire_unopened_everywhere
from study.services.errors import Conflict
from study.services.sessions import (
    claim,
    get_session,
    mark_dead_interrupted,
    set_status,
    silent_sessions,
)

log = logging.getLogger(__name__)
HUB_KINDS: dict[type, str] = {
    Progress: "progress",
    AdviceRequest: "advice_request",
    AdviceResult: "advice_result",
    EpisodeDone: "episode",
    SceneReset: "scene_reset",
    SceneStep: "scene_step",
    StatusChanged: "status",
}
HISTORY = 10
COMMAND_TIMEOUT_S = 120.0
STARTUP_LIMIT_S = 180.0
COALESCE_S = 0.05


@dataclass
class HistoryEntry:
    advice_index: int
    action: int
    global_step: int
    """The step advised: the robot's own moves since are counted from it."""
    reward: float | None = None


@dataclass
class WorkerHandle:
    session_id: int
    token: str
    process: Any
    conn: Connection
    advice_budget: int
    given: dict[int, int]
    status: str = Status.running.value
    killed: bool = False
    """The web process killed its worker (`SessionManager._kill`), which records the status."""
    progress: Progress | None = None
    request: AdviceRequest | None = None
    request_arrived: float = 0.0
    shown_at: float | None = None
    moving: bool = False
    ready: bool = False
    """The participant consented and finished the induction (human sessions)."""
    queued: bool = False
    """Waiting for a trainer slot after its advice."""
    training: bool = False
    """Holds a trainer slot."""
    training_since: float | None = None
    """`time.monotonic()` when it took its slot, and the episodes done then: how fast it
    trains, for the queue's time estimate."""
    episodes_at_slot: int = 0
    run: RunSpec | None = None
    """A human session's run: its population key is taken from it when it asks to train."""
    population_key: Any = None
    """What it must share with other sessions to train with them in one population once its
    advice is over (`population_key`); None: it trains alone."""
    population_size: int = 1
    """How many sessions its population may hold at most."""
    slot: object | None = None
    """The trainer slot it shares with the rest of its population (None: a slot of its
    own, or none)."""
    handing_over: bool = False
    """Its worker checkpoints and exits, for its population's worker to go on (this handle
    is then replaced by one on the population's worker)."""
    in_population: bool = False
    """It trains in a population's worker (`process` and `conn` are the population's)."""
    steps_before_first_turn: int = 0
    """Random pretraining steps before the first advice (what the page's progress counts)."""
    human: bool = False
    """A person advises it."""
    pooled: bool = False
    """It waits in its condition's pool (the pools keep their own count)."""
    last_reward: float | None = None
    history: deque[HistoryEntry] = field(default_factory=lambda: deque(maxlen=HISTORY))
    started: float = field(default_factory=time.monotonic)
    reported: bool = False
    """The worker has said something: it is past its start (imports, resuming)."""
    stopping: bool = False
    """The researcher asked it to stop: if it hangs, it ends `stopped`, not `interrupted`."""
    advice_lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    send_lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def at_first_turn(self) -> bool:
        """Its random pretraining is over: it asks for advice, or waits for its participant
        to be ready for it."""
        progress = self.progress
        done = progress.global_step if progress is not None else 0
        waiting = progress is not None and progress.waiting_for_participant
        return self.request is not None or waiting or done >= self.steps_before_first_turn

    def send(self, message: Any) -> bool:
        with self.send_lock:
            try:
                self.conn.send(message)
                return True
            except (BrokenPipeError, EOFError, OSError):
                return False


WORKER_PRELOAD = ("torch", "pybullet", "learner.trainer", "sim.env", "runs.worker.worker")
"""What every session worker imports, loaded once in the fork server: `import torch` alone
leaves about 140 MB of private memory in a process; forked from a server that holds it,
the workers share those pages (copy on write) instead of each making its own."""


def worker_context() -> (
    multiprocessing.context.ForkServerContext | multiprocessing.context.SpawnContext
):
    """Session workers are forked from a fork server that has loaded `WORKER_PRELOAD`
    (a clean single-threaded process started for the purpose, never the web process with
    its threads), or spawned where the platform has no fork server. Each worker still
    owns its PyBullet client, torch threads and everything it makes after the fork."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(WORKER_PRELOAD))
    return context


RESUME_WITHIN_S = 3600.0
"""How recent a lab session's last sign of life must be for a restart to resume it (an
online study's own idle limit decides for its visits)."""


def resumes_after_restart(session: StudySession, now: datetime) -> bool:
    """Whether the server's start resumes this interrupted session by itself: a person's
    session (not a pool's) that this version's shutdown in order interrupted (its detail),
    while the person could still be there: its last heartbeat within its idle limit (an
    online study's visit), else within `RESUME_WITHIN_S`. Older, paused, crashed and machine
    sessions stay for the researcher: resuming a visit whose person left long ago would only
    hold a worker until the idle limit ends it as abandoned."""
    if session.method != "human" or session.pooled:
        return False
    if not (session.status_detail or "").startswith(SHUTTING_DOWN):
        return False
    last = session.heartbeat_at or session.started_at
    if last is None:
        return False
    limit = session.idle_limit_s or RESUME_WITHIN_S
    return (now - last).total_seconds() <= limit


class SessionManager:
    def __init__(
        self,
        factory: sessionmaker[Session],
        database_url: str,
        hub: Hub,
        options: WorkerOptions,
        stale_after_s: float,
        max_trainers: int = 0,
        training_population: int = 0,
    ) -> None:
        """`max_trainers`: trainer slots for human sessions after their advice (0: the
        cores this process may use); `training_population`: sessions trained together in
        one slot at most (0: `default_population`, 1: each alone)."""
        self.max_trainers = max_trainers or len(os.sched_getaffinity(0))
        self.training_population = training_population
        self._handovers: set[asyncio.Task[None]] = set()
        self._closing = False
        self._train_queue: deque[int] = deque()
        self.cluster: TrainingCluster | None = None
        """A Ray cluster that trains the granted groups in place of this machine's slots."""
        self.factory = factory
        self.database_url = database_url
        self.hub = hub
        self.options = options
        self.stale_after_s = stale_after_s
        self.command_timeout_s = min(COMMAND_TIMEOUT_S, stale_after_s)
        """How long pause and stop wait for a worker; a hung one is killed by then."""
        self.handles: dict[int, WorkerHandle] = {}
        self._ahead: set[int] = set()
        """Sessions given a practice ahead of their participant, not started yet."""
        self._context = worker_context()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._versions = itertools.count(int(time.time() * 1000))
        self._version: dict[int, int] = {}
        self._changed: dict[int, asyncio.Event] = {}
        self._reaper: asyncio.Task[None] | None = None
        self._ending: set[asyncio.Task[None]] = set()
        """Visits ending after their worker gave up waiting (kept until done)."""
        hub.on_watchers_changed(self._watch)

    # --- lifecycle ---------------------------------------------------------------------
    async def open(self) -> None:
        self._loop = asyncio.get_running_loop()
        if isinstance(self._context, multiprocessing.context.ForkServerContext):
            # Loaded before the first participant arrives, not while they wait.
            threading.Thread(target=forkserver.ensure_running, daemon=True).start()
        await run_in_threadpool(self._reap)
        self._reaper = asyncio.create_task(self._reap_forever())

    async def resume_after_restart(self) -> list[int]:
        """Resume the participants' sessions that the last shutdown interrupted; their ids.

        A restart (an update, `systemctl restart`) would otherwise leave a person in the
        middle of a visit on "the researcher can resume it", with no researcher there in an
        online study. Machine sessions stay for their batch or researcher, pooled ones for
        their pool (which makes them again), and those a crash or a pause left for the
        researcher.
        """
        with self.factory() as db:
            interrupted = db.scalars(
                select(StudySession).where(
                    StudySession.status == Status.interrupted, StudySession.pooled.is_(False)
                )
            )
            now = utcnow()
            ids = [s.id for s in interrupted if resumes_after_restart(s, now)]
        resumed = []
        for session_id in ids:
            try:
                await self.resume(session_id)
            except Exception:  # it stays for the researcher; the others and the server go on
                log.exception("session %s did not resume after the restart", session_id)
            else:
                resumed.append(session_id)
        if resumed:
            log.info("resumed after the restart: sessions %s", resumed)
        return resumed

    def waiting_for_people(self) -> int:
        """Human sessions made by hand with a worker whose participant has not arrived yet
        (practising, or practised and waiting), and those about to start so: each holds a
        worker process."""
        live = {
            session_id
            for session_id, h in self.handles.items()
            if h.human and not h.pooled and not h.ready and h.status in LIVE_STATUSES
        }
        return len(live | self._ahead)

    def practise_ahead(self, session_id: int, limit: int) -> bool:
        """Whether the session may practise before its participant arrives: fewer than
        `limit` sessions wait for their people with a worker. If so it is counted from now;
        `welcome_ahead` then starts it. Otherwise it practises when its link is opened."""
        if self.waiting_for_people() >= limit:
            return False
        self._ahead.add(session_id)
        return True

    async def started_ahead(self, session_id: int, timeout_s: float = 30.0) -> None:
        """Wait while a practice `practise_ahead` allowed is starting (its worker claimed,
        not yet handled here), so whoever ends the session finds its worker."""
        deadline = time.monotonic() + timeout_s
        while session_id in self._ahead and time.monotonic() < deadline:
            await asyncio.sleep(0.05)

    async def welcome_ahead(self, session_id: int) -> None:
        """Start the practice `practise_ahead` allowed."""
        try:
            await self.welcome(session_id)
        finally:
            self._ahead.discard(session_id)

    async def close(self) -> None:
        """Server shutdown: workers checkpoint and become `interrupted` (resumable)."""
        self._closing = True
        if self._reaper is not None:
            self._reaper.cancel()
        handles = list(self.handles.values())
        for handle in handles:
            handle.send(Command("shutdown"))
        for handle in handles:
            await run_in_threadpool(join, handle.process, 60)
            if handle.process.is_alive():
                handle.process.terminate()

    def _reap(self) -> list[int]:
        """Mark sessions whose worker died, and kill our own workers that stopped beating."""
        # A starting worker (importing torch, replaying a checkpoint's episode) is judged
        # by its heartbeat only once it reports in, or after STARTUP_LIMIT_S.
        starting = time.monotonic() - STARTUP_LIMIT_S
        owned = {
            sid: h
            for sid, h in self.handles.items()
            if h.status in LIVE_STATUSES and (h.reported or h.started < starting)
        }
        # The silent workers are found (a read) and killed before anything is written: one
        # stopped in the middle of its own write holds the database's write lock until it
        # dies, and a write here would wait for it, fail, and never reach the kill.
        with self.factory() as db:
            silent = silent_sessions(db, self.stale_after_s, set(owned))
        marked: list[int] = []
        for session_id, token in silent:
            handle = owned[session_id]
            if handle.token != token:
                continue
            silence = f"its worker stopped marking itself alive for {self.stale_after_s:.0f} s"
            if handle.stopping:  # `stop` waits for it: what the researcher asked for
                detail = f"stopped by the researcher; {silence} and was killed (it resumes "
                detail += "from its last checkpoint)"
                self._kill(handle, Status.stopped, detail)
                self.hub.publish(session_id, "status", StatusChanged(Status.stopped.value))
                continue
            self._kill(handle, Status.interrupted, f"{silence} and was killed; resume it")
            marked.append(session_id)
        with self.factory() as db:
            marked += mark_dead_interrupted(db, self.stale_after_s, set(self.handles))
            expire_unopened_everywhere(db)  # links never opened free their place on time
        for session_id in marked:
            self.hub.publish(session_id, "status", StatusChanged(Status.interrupted.value))
        return marked

    def _kill(
        self, handle: WorkerHandle, status: Status, detail: str, level: int = logging.WARNING
    ) -> None:
        """Kill a worker that does not answer (or is no longer needed; SIGKILL works on a
        stopped process too), then record `status`: a worker stopped in its own write holds
        the database until it dies. Its last checkpoint stays."""
        handle.status = status.value
        handle.killed = True
        with contextlib.suppress(Exception):
            handle.process.kill()
        join(handle.process, 5)
        self._set_status(handle.session_id, status, detail, handle.token)
        log.log(level, "session %s: %s", handle.session_id, detail)
        self._call_soon(self.notify, handle.session_id)

    async def _reap_forever(self) -> None:
        while True:
            await asyncio.sleep(max(1.0, self.options.heartbeat_s * 2))
            try:
                await run_in_threadpool(self._reap)
            except Exception:
                log.exception("checking for dead workers failed")

    # --- researcher commands -----------------------------------------------------------
    async def start(
        self,
        session_id: int,
        resume: bool = False,
        override_numerics: bool = False,
        pooled: bool = False,
    ) -> None:
        """Start (or resume) the session's worker; `pooled`: it waits in its condition's
        pool for an arrival, its idle limit off until `assign`."""
        token, spec = await run_in_threadpool(self._claim, session_id, resume, override_numerics)
        parent, child = self._context.Pipe(duplex=True)
        with self.factory() as db:
            session = get_session(db, session_id)
            advice = db.scalars(
                select(Advice).where(Advice.session_id == session_id).order_by(Advice.advice_index)
            ).all()
            budget = spec.advice_budget
            human = session.method == "human"
            ready = human and session.ready_for_advice
            strategy = spec.make_strategy() or make_strategy("early", 0)
            first_turn = strategy.first_advice_step(spec.config.pretraining_steps) - 1
            run = spec if human else None
        # People wait on human sessions; machine sessions yield the CPU to them, and so
        # does a human session once its advice is over.
        options = (
            replace(
                self.options,
                nice=0,
                idle=False,
                train_nice=self.options.nice,
                train_idle=self.options.idle,
                pooled=pooled,
            )
            if human
            else self.options
        )
        process = self._context.Process(
            target=worker_main,
            args=(session_id, self.database_url, options, token, child),
            name=f"ideeprl-session-{session_id}",
            daemon=True,
        )
        # (an advice row without an action is a replay's request past its recorded stream:
        # nothing was given there)
        answered = [
            (a.advice_index, a.action, a.global_step) for a in advice if a.action is not None
        ]
        given = {index: action for index, action, _ in answered}
        handle = WorkerHandle(session_id, token, process, parent, budget, given)
        handle.history.extend(HistoryEntry(*row) for row in answered)
        handle.steps_before_first_turn = first_turn
        handle.human, handle.pooled = human, pooled
        handle.run = run
        try:
            process.start()
        except Exception as error:
            await run_in_threadpool(self._set_status, session_id, Status.failed, str(error), token)
            raise
        child.close()
        self.handles[session_id] = handle
        threading.Thread(
            target=self._read, args=(handle,), name=f"session-{session_id}-reader", daemon=True
        ).start()
        if self.hub.watchers(session_id):
            handle.send(Command("watch"))
        if ready:
            self.set_ready(session_id)
        self.hub.publish(session_id, "status", StatusChanged(Status.running.value))
        self.notify(session_id)

    def assign(self, session_id: int) -> None:
        """A pooled session was given to an arrival: its idle limit runs from now."""
        handle = self.handles.get(session_id)
        if handle is not None:
            handle.send(Command("assigned"))

    def set_ready(self, session_id: int) -> None:
        """The participant consented and finished the induction: advice may be asked."""
        handle = self.handles.get(session_id)
        if handle is not None and not handle.ready:
            handle.ready = True
            handle.send(Command("ready"))
            self.notify(session_id)

    def _grant_training(self) -> None:
        """Hand free trainer slots to the sessions queued longest, each with the queued
        sessions that can train with it in one population (`next_group`, as the batch)."""
        while True:
            free = self.max_trainers - self._busy_slots()
            waiting = self._waiting()
            self._train_queue = deque(h.session_id for h in waiting)
            if free <= 0 or not waiting:
                return
            group = self._next_group(waiting, free)
            taken = {h.session_id for h in group}
            self._train_queue = deque(sid for sid in self._train_queue if sid not in taken)
            if self.cluster is not None:  # the cluster trains the group (server.live.cluster)
                self.cluster.take(group, self.handles, self.notify, self.command_timeout_s)
                continue
            slot = object() if len(group) > 1 else None
            for handle in group:
                handle.queued = False
                handle.training = True
                handle.training_since = time.monotonic()
                handle.episodes_at_slot = handle.progress.episode if handle.progress else 0
                handle.slot = slot
                handle.handing_over = slot is not None
                handle.send(Command("handover" if slot is not None else "train"))
                self.notify(handle.session_id)
            if slot is not None:
                assert self._loop is not None
                task = self._loop.create_task(self._start_population(group, slot))
                self._handovers.add(task)
                task.add_done_callback(self._handovers.discard)

    def _waiting(self) -> list[WorkerHandle]:
        """The queued sessions, longest queued first."""
        handles = (self.handles.get(sid) for sid in dict.fromkeys(self._train_queue))
        return [h for h in handles if h is not None and h.queued]

    @staticmethod
    def _next_group(waiting: list[WorkerHandle], free: int) -> list[WorkerHandle]:
        """`next_group` of the queued sessions; a paused one takes a slot alone (granted
        like any other, it resumes where it waits)."""

        keys = [h.population_key if h.status == Status.running else None for h in waiting]
        return next_group(waiting, keys, waiting[0].population_size, free)

    def _busy_slots(self) -> int:
        """Trainer slots taken: a session training alone, or a population."""
        return len({id(h.slot or h) for h in self.handles.values() if h.training})

    async def _start_population(self, group: list[WorkerHandle], slot: object) -> None:
        """Once the group's workers have handed their sessions over (checkpointed and
        exited), train the sessions still running under their tokens in one population
        worker; each gets a handle of its own on that worker."""
        for handle in group:
            await run_in_threadpool(join, handle.process, self.command_timeout_s)
            if handle.process.is_alive():  # it resumes from its last checkpoint
                log.warning("session %s: its worker did not hand over; killed", handle.session_id)
                await run_in_threadpool(self._terminate, handle)
        tokens = await run_in_threadpool(self._still_ours, group)
        members = [h for h in group if h.session_id in tokens]
        if members and self._closing:
            detail = f"{SHUTTING_DOWN} as it started training"
            for handle in members:
                await run_in_threadpool(
                    self._set_status, handle.session_id, Status.interrupted, detail, handle.token
                )
            members = []
        process = None
        if members:
            ids = [h.session_id for h in members]
            parent, child = self._context.Pipe(duplex=True)
            options = replace(self.options, pooled=False, train_nice=0)
            process = self._context.Process(
                target=population_main,
                args=(ids, tokens, self.database_url, options, child),
                name=f"ideeprl-population-{'-'.join(map(str, ids))}",
                daemon=True,
            )
            try:
                process.start()
            except Exception as error:
                for handle in members:
                    await run_in_threadpool(
                        self._set_status, handle.session_id, Status.failed, str(error), handle.token
                    )
                members, process = [], None
            else:
                child.close()
        joined: dict[int, WorkerHandle] = {}
        sending = threading.Lock()  # one pipe for all of them
        for old in group:
            if self.handles.get(old.session_id) is old:
                del self.handles[old.session_id]
            old.training = False  # `handing_over` stays: its worker's exit is no death
            if not any(h is old for h in members):
                self.notify(old.session_id)
                continue
            assert process is not None and old.progress is not None
            handle = WorkerHandle(
                old.session_id, old.token, process, parent, old.advice_budget, old.given
            )
            handle.progress = replace(old.progress, queued=False)
            handle.history = old.history
            handle.last_reward, handle.ready = old.last_reward, old.ready
            handle.steps_before_first_turn = old.steps_before_first_turn
            handle.population_key, handle.population_size = old.population_key, len(members)
            handle.training, handle.slot, handle.in_population = True, slot, True
            handle.send_lock = sending
            handle.training_since = time.monotonic()
            handle.episodes_at_slot = handle.progress.episode
            self.handles[old.session_id] = handle
            joined[old.session_id] = handle
            if self.hub.watchers(old.session_id):  # a page still shows its training
                handle.send(Command("watch", session_id=old.session_id))
            self.notify(old.session_id)
        if joined:
            threading.Thread(
                target=self._read_population,
                args=(parent, process, joined),
                name=f"population-{'-'.join(map(str, joined))}-reader",
                daemon=True,
            ).start()
        self._grant_training()  # a slot of sessions that did not come is free again

    def _still_ours(self, group: list[WorkerHandle]) -> dict[int, str]:
        """Of the group, the sessions still `running` under their worker's token (not
        stopped, failed or taken back meanwhile): their tokens."""
        with self.factory() as db:
            tokens = {}
            for handle in group:
                session = get_session(db, handle.session_id)
                if session.status == Status.running and session.worker_token == handle.token:
                    tokens[handle.session_id] = handle.token
            return tokens

    @staticmethod
    def _terminate(handle: WorkerHandle) -> None:
        with contextlib.suppress(Exception):
            handle.process.kill()
        join(handle.process, 5)

    def set_trainer_slots(self, slots: int) -> None:
        """Change how many human sessions may train at once (0: none); freed slots go to
        the queue at once. Sessions already training keep theirs."""
        assert slots >= 0
        self.max_trainers = slots
        self._grant_training()

    def _queue_plan(self) -> list[list[WorkerHandle]]:
        """The queued sessions in the groups they will take trainer slots in, in order: as
        `_grant_training` takes them when a slot frees (`next_group` with one free slot)."""
        waiting, plan = self._waiting(), []
        while waiting:
            group = self._next_group(waiting, 1)
            plan.append(group)
            taken = {h.session_id for h in group}
            waiting = [h for h in waiting if h.session_id not in taken]
        return plan

    def queue_place(self, session_id: int) -> int | None:
        """1 for the queued sessions that take the next trainer slot to free (several
        together, as a population), 2 for those after, ...; None when the session is not
        queued."""
        handle = self.handles.get(session_id)
        if handle is None or not handle.queued:
            return None
        for place, group in enumerate(self._queue_plan(), 1):
            if any(h.session_id == session_id for h in group):
                return place
        return None

    def queue_wait_s(self, session_id: int) -> float | None:
        """Seconds until a queued session gets a slot, estimated from how fast the sessions
        in the slots train now. Speed is counted per agent-episode: a slot whose n sessions
        (a population, or one alone) each take r seconds an episode runs one agent-episode
        every r / n seconds. A slot frees when its slowest session has run its remaining
        episodes; each group ahead in the queue (`_queue_plan`) then holds the earliest
        free slot while its m sessions run theirs, m side by side at the typical speed. None
        while no session in a slot has finished an episode there (nothing to estimate
        from)."""
        place = self.queue_place(session_id)
        if place is None or self.max_trainers <= 0:
            return None
        now = time.monotonic()
        slots: dict[int, list[WorkerHandle]] = {}
        for h in self.handles.values():
            if h.training and h.progress is not None:
                slots.setdefault(id(h.slot or h), []).append(h)
        rates: dict[int, float] = {}  # seconds an episode, each session in its slot
        costs: list[float] = []  # seconds an agent-episode, per measured session
        for members in slots.values():
            live = max(1, sum(1 for h in members if self._episodes_left(h)))
            for h in members:
                assert h.progress is not None
                done = h.progress.episode - h.episodes_at_slot
                if h.training_since is not None and done > 0:
                    rates[h.session_id] = (now - h.training_since) / done
                    costs.append(rates[h.session_id] / live)
        if not costs:
            return None
        typical = sum(costs) / len(costs)
        frees = [0.0] * max(0, self.max_trainers - len(slots))
        for members in slots.values():
            live = max(1, sum(1 for h in members if self._episodes_left(h)))
            frees.append(
                max(
                    self._episodes_left(h) * rates.get(h.session_id, typical * live)
                    for h in members
                )
            )
        frees.sort()
        for group in self._queue_plan()[: place - 1]:
            longest = max(self._episodes_left(h) for h in group)
            frees[0] += longest * typical * len(group)
            frees.sort()
        return frees[0]

    @staticmethod
    def _episodes_left(handle: WorkerHandle) -> int:
        """Training episodes the session has yet to run (none once it has ended)."""
        if handle.progress is None or handle.status not in LIVE_STATUSES:
            return 0
        return max(0, handle.progress.episodes - handle.progress.episode)

    def _claim(
        self, session_id: int, resume: bool, override_numerics: bool = False
    ) -> tuple[str, RunSpec]:
        """The session claimed for a worker of this process, and its run as this machine
        computes it (read here once, and passed on)."""
        with self.factory() as db:
            session = get_session(db, session_id)
            spec = numerics.settle(db, session, session.spec, override_numerics)
            return claim(db, session_id, resume), spec

    def _set_status(self, session_id: int, status: Status, detail: str, token: str) -> None:
        with self.factory() as db:
            set_status(db, session_id, status, detail, token=token)

    async def welcome(self, session_id: int) -> None:
        """The participant opened their link or finished the induction: make sure a worker
        runs for their session. A new session starts (its random pretraining runs while they
        read); one abandoned because they did not come before its first advice resumes.
        A start at the same moment elsewhere, or one that cannot start, is left alone."""
        handle = self.handles.get(session_id)
        if handle is not None and handle.status in LIVE_STATUSES:
            return
        with self.factory() as db:
            session = get_session(db, session_id)
            waited_for_them = (
                session.status == Status.abandoned
                and session.status_detail.startswith(WAITED_FOR_PARTICIPANT)
            )
            if session.status != Status.created and not waited_for_them:
                return
        with contextlib.suppress(Conflict):
            await self.start(session_id, resume=waited_for_them)

    async def pause(self, session_id: int) -> None:
        handle = self._live(session_id, "pause")
        if handle.in_population or handle.handing_over:
            raise Conflict(
                f"session {session_id} trains together with other sessions in one process "
                "and cannot pause alone; stop it instead (it resumes from its last checkpoint)"
            )
        if handle.status != Status.paused:
            handle.send(Command("pause"))
            await self._until(session_id, lambda h: h.status != Status.running)

    async def resume(self, session_id: int, override_numerics: bool = False) -> None:
        handle = self.handles.get(session_id)
        if handle is not None and handle.status in LIVE_STATUSES:
            if handle.status == Status.paused:
                handle.send(Command("resume"))
                await self._until(session_id, lambda h: h.status != Status.paused)
            return
        with self.factory() as db:
            status = get_session(db, session_id).status
        if status == Status.created:
            raise Conflict(f"session {session_id} has not started; start it instead")
        await self.start(session_id, resume=True, override_numerics=override_numerics)

    async def stop(self, session_id: int) -> None:
        handle = self.handles.get(session_id)
        if handle is None or handle.status not in LIVE_STATUSES:
            with self.factory() as db:
                session = get_session(db, session_id)
                if session.status in (Status.created, *RESUMABLE_STATUSES):
                    set_status(db, session_id, Status.stopped, "stopped by the researcher")
                    self.notify(session_id)
                    return
            raise Conflict(f"session {session_id} is {session.status}; there is nothing to stop")
        if handle.handing_over:  # stop it where it goes on
            await self._until(session_id, lambda h: not h.handing_over)
            return await self.stop(session_id)
        handle.stopping = True
        if handle.in_population:  # the others go on
            handle.send(Command("stop", session_id=session_id))
            await self._until(session_id, lambda h: h.status not in LIVE_STATUSES)
            return
        handle.send(Command("stop"))
        await run_in_threadpool(join, handle.process, self.command_timeout_s)
        if handle.process.is_alive():
            detail = (
                f"stopped by the researcher; its worker did not answer within "
                f"{self.command_timeout_s:.0f} s and was killed (it resumes from its last "
                "checkpoint)"
            )
            await run_in_threadpool(self._kill, handle, Status.stopped, detail)

    async def end(self, session_id: int, status: Status, detail: str) -> None:
        """End a session for good now (a visit that ended early): its worker, if one runs,
        is killed at once (nothing of it is needed again) and the status recorded."""
        handle = self.handles.get(session_id)
        if handle is not None and handle.status in LIVE_STATUSES:
            await run_in_threadpool(self._kill, handle, status, detail, logging.INFO)
        else:
            with self.factory() as db:
                set_status(db, session_id, status, detail)
        self.hub.publish(session_id, "status", StatusChanged(status.value, detail))

    def _live(self, session_id: int, verb: str) -> WorkerHandle:
        handle = self.handles.get(session_id)
        if handle is None or handle.status not in LIVE_STATUSES:
            with self.factory() as db:
                status = get_session(db, session_id).status
            raise Conflict(f"session {session_id} is {status}; only a running session can {verb}")
        return handle

    async def _until(self, session_id: int, done: Callable[[WorkerHandle], bool]) -> None:
        deadline = time.monotonic() + self.command_timeout_s
        while time.monotonic() < deadline:
            handle = self.handles.get(session_id)
            if handle is None or done(handle):
                return
            await self.wait_change(session_id, self.version(session_id), 1.0)
        raise Conflict(f"session {session_id} did not answer within {self.command_timeout_s:.0f} s")

    def status(self, session_id: int) -> str:
        """The live status if a worker runs, else the stored one."""
        handle = self.handles.get(session_id)
        if handle is not None:
            return handle.status
        with self.factory() as db:
            return get_session(db, session_id).status

    # --- change notification (long-poll) ------------------------------------------------
    def version(self, session_id: int) -> int:
        if session_id not in self._version:
            self._version[session_id] = next(self._versions)
        return self._version[session_id]

    async def wait_change(self, session_id: int, after: int, timeout: float) -> None:
        """Return when the session's participant-visible state is newer than `after`."""
        if self.version(session_id) > after:
            return
        event = self._changed.setdefault(session_id, asyncio.Event())
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(event.wait(), timeout)

    def _notify_soon(self, session_id: int) -> None:
        """Notify unless something else does first: the next advice request usually follows
        an advice's result within milliseconds, and one wake-up then serves both."""
        assert self._loop is not None
        version = self.version(session_id)

        def later() -> None:
            if self.version(session_id) == version:
                self.notify(session_id)

        self._loop.call_later(COALESCE_S, later)

    def notify(self, session_id: int) -> None:
        self._version[session_id] = next(self._versions)
        event = self._changed.pop(session_id, None)
        if event is not None:
            event.set()

    # --- messages from workers ---------------------------------------------------------
    def _read(self, handle: WorkerHandle) -> None:
        """Reader thread: one per worker, until its pipe closes."""
        assert self._loop is not None
        while True:
            try:
                message = handle.conn.recv()
            except (EOFError, OSError):
                break
            kind = HUB_KINDS.get(type(message))
            if kind is not None:
                self.hub.publish(handle.session_id, kind, message)
            self._call_soon(self._apply, handle, message)
        self._exited(handle, join(handle.process, 10))

    def _read_population(
        self, conn: Connection, process: Any, members: dict[int, WorkerHandle]
    ) -> None:
        """Reader thread of a population's worker: each message to its session's handle."""
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):
                break
            handle = members.get(message.session_id) if isinstance(message, Tagged) else None
            if handle is None:
                continue
            kind = HUB_KINDS.get(type(message.message))
            if kind is not None:
                self.hub.publish(handle.session_id, kind, message.message)
            self._call_soon(self._apply, handle, message.message)
        code = join(process, 10)
        for handle in members.values():
            self._exited(handle, code)

    def _exited(self, handle: WorkerHandle, code: int | None) -> None:
        """The session's worker is gone: if it left the session live, it died."""
        if handle.handing_over:  # the session goes on in its population's worker
            return
        if handle.killed:  # `_kill` records why, once it is gone
            self._call_soon(self._drop, handle)
            return
        with self.factory() as db:
            session = get_session(db, handle.session_id)
            died = session.status in LIVE_STATUSES and session.worker_token == handle.token
            if died:
                detail = f"its worker exited unexpectedly (exit code {code}); resume it"
                set_status(db, handle.session_id, Status.interrupted, detail, token=handle.token)
            final = session.status
        if died:
            self.hub.publish(handle.session_id, "status", StatusChanged(final, detail))
        self._call_soon(self._drop, handle)

    def _call_soon(self, callback: Any, *args: Any) -> None:
        """Hand work to the event loop, unless the server has already shut it down."""
        assert self._loop is not None
        # RuntimeError: the loop closed between the check and the call.
        with contextlib.suppress(RuntimeError):
            if not self._loop.is_closed():
                self._loop.call_soon_threadsafe(callback, *args)

    def _apply(self, handle: WorkerHandle, message: Any) -> None:
        handle.reported = True
        if isinstance(message, Progress):
            handle.progress = message
            return
        if isinstance(message, AdviceRequest):
            handle.request = message
            handle.request_arrived = time.monotonic()
            handle.shown_at = None
            handle.moving = False
        elif isinstance(message, AdviceResult):
            handle.moving = False
            handle.last_reward = message.reward
            for entry in handle.history:
                if entry.advice_index == message.advice_index:
                    entry.reward = message.reward
            self._notify_soon(handle.session_id)
            return
        elif isinstance(message, StatusChanged):
            handle.status = message.status
            if message.status == Status.abandoned:
                assert self._loop is not None
                task = self._loop.create_task(visits.abandoned(self, handle.session_id))
                self._ending.add(task)
                task.add_done_callback(self._ending.discard)
        elif isinstance(message, TrainingWanted):
            if handle.run is not None:
                handle.population_key = population_key(handle.run, advice_over=True)
                handle.population_size = self.training_population or default_population(
                    handle.run, workers=self.max_trainers
                )
            handle.queued = True
            self._train_queue.append(handle.session_id)
            self._grant_training()
        else:
            return
        self.notify(handle.session_id)

    def _drop(self, handle: WorkerHandle) -> None:
        if handle.handing_over:  # `_start_population` replaces it
            return
        if self.handles.get(handle.session_id) is handle:
            del self.handles[handle.session_id]
        if handle.training or handle.queued:
            handle.training = handle.queued = False
            self._grant_training()
        self.notify(handle.session_id)

    def _watch(self, session_id: int, watched: bool) -> None:
        handle = self.handles.get(session_id)
        if handle is not None:
            # named: a population's worker passes it to that session alone
            handle.send(Command("watch" if watched else "unwatch", session_id=session_id))
