"""The web process's side of the running sessions, coordinated: the manager starts, pauses,
resumes, stops and kills each session's worker (the processes and their pipes are
`server.live.workers`'), reaps the dead and the silent, and hands each message a worker
sends to the part it concerns, on the event loop's thread: the session's `LiveSession`
(what the participant's page reads) and the trainer slots (`server.live.trainers`).

A human session asks for advice only once its participant is ready (consent and induction
recorded; the manager then sends `Command("ready")`), and trains after its advice only in
one of the trainer slots (`server.live.trainers`), which the manager asks for on the
session's behalf. A slot given to one session lets its worker train on; one given to
several hands them over (`Command("handover")`: each worker checkpoints and exits, the
session still `running` under its token) to one population worker (`population_main`),
which sends each session's messages `Tagged` with it, so each keeps its own handle,
progress, records, checkpoints and status.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from learner.run import RunSpec
from runs.worker.cluster import Handed
from runs.worker.link import SHUTTING_DOWN, WAITED_FOR_PARTICIPANT
from runs.worker.messages import AdviceRequest, Command, StatusChanged, TrainingWanted
from runs.worker.worker import WorkerOptions
from server.live import visits
from server.live.cluster import TrainingCluster
from server.live.hub import Hub
from server.live.reaping import join
from server.live.session import Changes, LiveSession
from server.live.trainers import Seat, TrainerSlots
from server.live.workers import WorkerHandle, Workers
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
from study.services.feedback import rated_turns
from study.services.sessions import (
    claim,
    get_session,
    mark_dead_interrupted,
    set_status,
    silent_sessions,
)

log = logging.getLogger(__name__)
COMMAND_TIMEOUT_S = 120.0
STARTUP_LIMIT_S = 180.0
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
        self.trainers = TrainerSlots(
            max_trainers or len(os.sched_getaffinity(0)),
            training_population,
            self._seats,
            self._granted,
        )
        self._handovers: set[asyncio.Task[None]] = set()
        self._closing = False
        self.cluster: TrainingCluster | None = None
        """A Ray cluster that trains the granted groups in place of this machine's slots
        (the slots are then its CPUs, `TrainingCluster.bind`)."""
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
        self.workers = Workers(database_url, hub, self._deliver, self._exited)
        self._loop: asyncio.AbstractEventLoop | None = None
        self.changes = Changes()
        self._reaper: asyncio.Task[None] | None = None
        self._ending: set[asyncio.Task[None]] = set()
        """Visits ending after their worker gave up waiting (kept until done)."""
        self.on_request: Callable[[WorkerHandle, AdviceRequest], None] = lambda h, r: None
        """Called on the event loop as a turn's request arrives (`server.live.rating`)."""
        hub.on_watchers_changed(self._watch)

    # --- lifecycle ---------------------------------------------------------------------
    async def open(self) -> None:
        self._loop = asyncio.get_running_loop()
        if self.cluster is not None:  # its capacity is the number of trainer slots
            self.cluster.bind(
                self.changes.notify,
                self.trainers.release,
                self.trainers.set_slots,
                self._practised,
            )
        self.workers.warm()
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
            if h.live.human
            and not h.live.pooled
            and not h.live.ready
            and h.live.status in LIVE_STATUSES
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
        await run_in_threadpool(self.workers.shut_down, list(self.handles.values()))

    def _reap(self) -> list[int]:
        """Mark sessions whose worker died, and kill our own workers that stopped beating."""
        # A starting worker (importing torch, replaying a checkpoint's episode) is judged
        # by its heartbeat only once it reports in, or after STARTUP_LIMIT_S.
        starting = time.monotonic() - STARTUP_LIMIT_S
        owned = {
            sid: h
            for sid, h in self.handles.items()
            if h.live.status in LIVE_STATUSES and (h.reported or h.started < starting)
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
        handle.live.set_status(status.value)
        handle.killed = True
        self.workers.kill(handle)
        self._set_status(handle.session_id, status, detail, handle.token)
        log.log(level, "session %s: %s", handle.session_id, detail)
        self._call_soon(self.changes.notify, handle.session_id)

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
        pool for an arrival, its idle limit off until `assign`. With a Ray cluster a machine
        session (no person advises it) trains there, as a human one does after its advice,
        and a pool's session practises there (`_practised` takes it back at its first turn);
        either holds one of the cluster's trainer slots until its task ends."""
        token, spec = await run_in_threadpool(self._claim, session_id, resume, override_numerics)
        with self.factory() as db:
            human = get_session(db, session_id).method == "human"
        if self.cluster is not None and (not human or pooled):
            practice = human  # a pool's practice; else a replay, a fitted or an oracle's run
            first_turn = spec.steps_before_first_turn() if practice else 0
            live = LiveSession(session_id, spec.advice_budget, [], self.changes, first_turn)
            handed = Handed(session_id, token)
            await run_in_threadpool(self.cluster.train, handed, Seat(live), spec, practice)
        else:
            self._start_here(session_id, token, spec, pooled)
            return
        self.hub.publish(session_id, "status", StatusChanged(Status.running.value))
        self.changes.notify(session_id)

    def _start_here(self, session_id: int, token: str, spec: RunSpec, pooled: bool) -> None:
        """The session's worker in a process of this machine, under `token`."""
        with self.factory() as db:
            session = get_session(db, session_id)
            advice = db.scalars(
                select(Advice).where(Advice.session_id == session_id).order_by(Advice.advice_index)
            ).all()
            human = session.method == "human"
            rated = rated_turns(db, session_id) if human else []  # a rating session's turns
            ready = human and session.ready_for_advice
            first_turn = spec.steps_before_first_turn()
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
        try:
            process, parent = self.workers.start(session_id, options, token)
        except Exception as error:
            self._set_status(session_id, Status.failed, str(error), token)
            raise
        # (an advice row without an action is a replay's request past its recorded stream:
        # nothing was given there)
        answered = [
            (a.advice_index, a.action, a.global_step) for a in advice if a.action is not None
        ] + [(f.feedback_index, f.action, f.global_step) for f in rated]
        live = LiveSession(
            session_id, spec.advice_budget, answered, self.changes, first_turn, human, pooled
        )
        handle = WorkerHandle(session_id, token, process, parent, live, Seat(live, run))
        self.handles[session_id] = handle
        self.workers.read(handle)
        if self.hub.watchers(session_id):
            handle.send(Command("watch"))
        if ready:
            self.set_ready(session_id)
        self.hub.publish(session_id, "status", StatusChanged(Status.running.value))
        self.changes.notify(session_id)

    def _practised(self, handed: Handed) -> None:
        """A pool's session practised on the cluster up to its first turn: its advice goes
        on in a worker here, from the checkpoint there (on the event loop's thread)."""
        assert self._loop is not None
        task = self._loop.create_task(self._back_from_practice(handed))
        self._handovers.add(task)
        task.add_done_callback(self._handovers.discard)

    async def _back_from_practice(self, handed: Handed) -> None:
        assert self.cluster is not None
        session_id = handed.session_id
        try:
            token = await run_in_threadpool(self.cluster.take_back, handed)
            if token is None:  # stopped, ended or deleted meanwhile
                return
            if self._closing:
                detail = f"{SHUTTING_DOWN} as its practice ended"
                await run_in_threadpool(
                    self._set_status, session_id, Status.interrupted, detail, token
                )
                return
            with self.factory() as db:
                session = get_session(db, session_id)
                spec = numerics.settle(db, session, session.spec, False)
                pooled = session.pooled  # not once an arrival has taken it meanwhile
            self._start_here(session_id, token, spec, pooled)
        except Exception:
            log.exception("session %s: its worker did not start after its practice", session_id)
        finally:
            self.cluster.returned(session_id)
            self.changes.notify(session_id)

    def practising_elsewhere(self, session_id: int) -> bool:
        """Its practice runs on the cluster, or is coming back to a worker here."""
        return self.cluster is not None and session_id in self.cluster.practising()

    def assign(self, session_id: int) -> None:
        """A pooled session was given to an arrival: its idle limit runs from now."""
        handle = self.handles.get(session_id)
        if handle is not None:
            handle.send(Command("assigned"))

    def set_ready(self, session_id: int) -> None:
        """The participant consented and finished the induction: advice may be asked."""
        handle = self.handles.get(session_id)
        if handle is not None and not handle.live.ready:
            handle.live.set_ready()
            handle.send(Command("ready"))

    def _seats(self) -> dict[int, Seat]:
        """The seats of the sessions with a worker here, and of those the cluster trains
        (each holds one of the cluster's slots until its task ends)."""
        seats = self.cluster.seats() if self.cluster is not None else {}
        return {**seats, **{session_id: h.seat for session_id, h in self.handles.items()}}

    def _granted(self, seats: list[Seat], slot: object | None) -> None:
        """A trainer slot for `seats`: one session trains on in its own worker; several
        hand their sessions over to one population worker."""
        group = [self.handles[seat.session_id] for seat in seats]
        if self.cluster is not None:  # the cluster trains the group (server.live.cluster)
            self.cluster.take(group, self.handles, self.command_timeout_s)
            return
        for handle in group:
            handle.handing_over = slot is not None
            handle.send(Command("handover" if slot is not None else "train"))
            self.changes.notify(handle.session_id)
        if slot is not None:
            assert self._loop is not None
            task = self._loop.create_task(self._start_population(group, slot))
            self._handovers.add(task)
            task.add_done_callback(self._handovers.discard)

    async def _start_population(self, group: list[WorkerHandle], slot: object) -> None:
        """Once the group's workers have handed their sessions over (checkpointed and
        exited), train the sessions still running under their tokens in one population
        worker; each gets a handle of its own on that worker."""
        for handle in group:
            await run_in_threadpool(join, handle.process, self.command_timeout_s)
            if handle.process.is_alive():  # it resumes from its last checkpoint
                log.warning("session %s: its worker did not hand over; killed", handle.session_id)
                await run_in_threadpool(self.workers.kill, handle)
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
            options = replace(self.options, pooled=False, train_nice=0)
            try:
                process, parent = self.workers.start_population(ids, tokens, options)
            except Exception as error:
                for handle in members:
                    await run_in_threadpool(
                        self._set_status, handle.session_id, Status.failed, str(error), handle.token
                    )
                members, process = [], None
        joined: dict[int, WorkerHandle] = {}
        sending = threading.Lock()  # one pipe for all of them
        for old in group:
            if self.handles.get(old.session_id) is old:
                del self.handles[old.session_id]
            self.trainers.vacate(old.seat)  # `handing_over` stays: its exit is no death
            if not any(h is old for h in members):
                self.changes.notify(old.session_id)
                continue
            assert process is not None
            live = old.live.handed_over()
            seat = self.trainers.joined(old.seat, live, len(members))
            handle = WorkerHandle(old.session_id, old.token, process, parent, live, seat)
            handle.in_population = True
            handle.send_lock = sending
            self.handles[old.session_id] = handle
            joined[old.session_id] = handle
            if self.hub.watchers(old.session_id):  # a page still shows its training
                handle.send(Command("watch", session_id=old.session_id))
            self.changes.notify(old.session_id)
        if joined:
            self.workers.read_population(parent, process, joined)
        self.trainers.grant()  # a slot of sessions that did not come is free again

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
        if handle is not None and handle.live.status in LIVE_STATUSES:
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
        if handle.live.status != Status.paused:
            handle.send(Command("pause"))
            await self._until(session_id, lambda h: h.live.status != Status.running)

    async def resume(self, session_id: int, override_numerics: bool = False) -> None:
        handle = self.handles.get(session_id)
        if handle is not None and handle.live.status in LIVE_STATUSES:
            if handle.live.status == Status.paused:
                handle.send(Command("resume"))
                await self._until(session_id, lambda h: h.live.status != Status.paused)
            return
        with self.factory() as db:
            status = get_session(db, session_id).status
        if status == Status.created:
            raise Conflict(f"session {session_id} has not started; start it instead")
        await self.start(session_id, resume=True, override_numerics=override_numerics)

    async def stop(self, session_id: int) -> None:
        handle = self.handles.get(session_id)
        if handle is None or handle.live.status not in LIVE_STATUSES:
            with self.factory() as db:
                session = get_session(db, session_id)
                if session.status in (Status.created, *RESUMABLE_STATUSES):
                    set_status(db, session_id, Status.stopped, "stopped by the researcher")
                    self.changes.notify(session_id)
                    return
            raise Conflict(f"session {session_id} is {session.status}; there is nothing to stop")
        if handle.handing_over:  # stop it where it goes on
            await self._until(session_id, lambda h: not h.handing_over)
            return await self.stop(session_id)
        handle.stopping = True
        if handle.in_population:  # the others go on
            handle.send(Command("stop", session_id=session_id))
            await self._until(session_id, lambda h: h.live.status not in LIVE_STATUSES)
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
        if handle is not None and handle.live.status in LIVE_STATUSES:
            await run_in_threadpool(self._kill, handle, status, detail, logging.INFO)
        else:
            with self.factory() as db:
                set_status(db, session_id, status, detail)
        self.hub.publish(session_id, "status", StatusChanged(status.value, detail))

    def _live(self, session_id: int, verb: str) -> WorkerHandle:
        handle = self.handles.get(session_id)
        if handle is None or handle.live.status not in LIVE_STATUSES:
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
            await self.changes.wait(session_id, self.changes.version(session_id), 1.0)
        raise Conflict(f"session {session_id} did not answer within {self.command_timeout_s:.0f} s")

    def live(self, session_id: int) -> LiveSession | None:
        """The session's advice turn as its page sees it, while a worker of this process
        runs it."""
        handle = self.handles.get(session_id)
        return handle.live if handle is not None else None

    def status(self, session_id: int) -> str:
        """The live status if a worker runs, else the stored one."""
        handle = self.handles.get(session_id)
        if handle is not None:
            return handle.live.status
        with self.factory() as db:
            return get_session(db, session_id).status

    # --- messages from workers ---------------------------------------------------------
    def _deliver(self, handle: WorkerHandle, message: Any) -> None:
        """A worker's message, from its reader thread: applied on the event loop's."""
        self._call_soon(self._apply, handle, message)

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
        handle.live.receive(message)
        if isinstance(message, AdviceRequest):
            self.on_request(handle, message)
        if isinstance(message, StatusChanged):
            if message.status == Status.abandoned:
                assert self._loop is not None
                task = self._loop.create_task(visits.abandoned(self, handle.session_id))
                self._ending.add(task)
                task.add_done_callback(self._ending.discard)
        elif isinstance(message, TrainingWanted):
            self.trainers.request(handle.seat)
            self.changes.notify(handle.session_id)

    def _drop(self, handle: WorkerHandle) -> None:
        if handle.handing_over:  # `_start_population` replaces it
            return
        if self.handles.get(handle.session_id) is handle:
            del self.handles[handle.session_id]
        self.trainers.release(handle.seat)
        self.changes.notify(handle.session_id)

    def _watch(self, session_id: int, watched: bool) -> None:
        handle = self.handles.get(session_id)
        if handle is not None:
            # named: a population's worker passes it to that session alone
            handle.send(Command("watch" if watched else "unwatch", session_id=session_id))
