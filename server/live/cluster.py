"""Training on a Ray cluster: the web process's side.

With a Ray address (`IDEEPRL_RAY_ADDRESS`, `ideeprl serve --ray-address`), the sessions a
trainer slot would take (a human session whose advice is over, alone or with the queued
sessions of its learner configuration) are handed to the cluster instead: each local
worker checkpoints and exits (`Command("handover")`), and the group trains as one Ray task
on any node (`runs.worker.cluster.train_handed`). The advice itself stays in the web
process's own workers, next to the participant.

A machine session started on the server (a replay, a fitted advisor's or an oracle's run:
no person advises it) goes to the cluster from its start, one task of its own
(`SessionManager.start`), with the records it would have in a local worker; its seat holds
one of the trainer slots from then until its task ends, so the queue counts its CPU. A
pool's session practises there too (`WorkerOptions.practice_only`), its seat held by the
same rule: its task ends at the step boundary before its first turn, checkpointed, and a
worker of the web process takes it on from that checkpoint to wait for its participant
next to them (`take_back`).

The database is the channel both ways: the task writes records, progress, checkpoints and
status, and reads the researcher's stop and pause from the session's row; the web process
reads a session without a local worker from there, as it does for any other. A group
waits for a node under a token of this process, which keeps it alive until the task
takes it; a task whose node died is started again on another node, each session from its
last checkpoint.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, MutableMapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

from sqlalchemy import select, update
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

from learner.run import RunSpec
from runs.worker.cluster import Handed, train_handed
from runs.worker.link import SHUTTING_DOWN
from runs.worker.messages import Command, Progress, StatusChanged
from runs.worker.worker import WorkerOptions
from server.live.hub import Hub
from server.live.reaping import join
from server.live.trainers import Seat
from study.db.models import Status, StudySession, utcnow
from study.services.errors import Conflict
from study.services.ownership import HOST
from study.services.sessions import set_status

log = logging.getLogger(__name__)
WAITING = "waiting for a node of the Ray cluster"
SHUT_DOWN = (
    f"{SHUTTING_DOWN} while it trained on the Ray cluster; it resumes from its last checkpoint"
)
ATTEMPTS = 3
"""Times a session is started on the cluster before it is left `interrupted` (its node
died each time)."""
WATCH_EVERY_S = 1.0
CAPACITY_EVERY_S = 10.0
"""How often the cluster's CPUs are read again (nodes join and leave)."""


def cluster_refusal(database_url: str, storage_root: Path) -> str | None:
    """Why the server cannot hand training to a cluster with this database and storage
    root (None: it can)."""
    if make_url(database_url).get_backend_name() == "sqlite":
        return (
            "a Ray address is set, but the database is SQLite: a file that only this machine "
            "can write, which the cluster's nodes cannot reach. Set IDEEPRL_DATABASE_URL to "
            "a PostgreSQL server every node reaches, or leave IDEEPRL_RAY_ADDRESS unset to "
            "train on this machine"
        )
    if not storage_root.is_dir():
        return (
            f"the storage root {storage_root} does not exist: mount the folder every node "
            "shares there (IDEEPRL_STORAGE_ROOT), or leave IDEEPRL_RAY_ADDRESS unset"
        )
    try:
        with tempfile.NamedTemporaryFile(dir=storage_root):
            pass
    except OSError as error:
        return f"the storage root {storage_root} is not writable here ({error.strerror})"
    return None


class HandedHandle(Protocol):
    """What the cluster needs of a session's handle in the web process."""

    session_id: int
    token: str
    process: Any
    handing_over: bool
    seat: Seat

    def send(self, message: Any) -> bool: ...


@dataclass
class _Task:
    handed: list[Handed]
    attempt: int = 1
    practice: bool = False
    """A pool's random practice: it ends at its session's first turn."""


class TrainingCluster:
    """The server's connection to a Ray cluster, and the groups training there."""

    def __init__(
        self,
        address: str,
        factory: sessionmaker[Session],
        database_url: str,
        options: WorkerOptions,
        hub: Hub,
        cpus_per_group: float = 1.0,
    ) -> None:
        self.address = address
        self.factory = factory
        self.database_url = database_url
        self.options = options
        self.hub = hub
        self.cpus_per_group = cpus_per_group
        self._tasks: dict[Any, _Task] = {}
        self._seats: dict[int, Seat] = {}
        """The trainer-slot seats of the sessions it trains (or hands over): they hold their
        slots until their task ends, so the queue counts the cluster's capacity."""
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._notify: Callable[[int], None] = lambda session_id: None
        self._release: Callable[[Seat], None] = lambda seat: None
        self._set_slots: Callable[[int], None] = lambda slots: None
        self._practised: Callable[[Handed], None] = lambda handed: None
        self._returning: set[int] = set()
        """Sessions whose practice ended, until a worker of the web process takes them."""
        self._capacity = 0
        self._capacity_read_at = 0.0
        self._closing = threading.Event()
        self._watcher: threading.Thread | None = None
        self._handovers: set[asyncio.Task[None]] = set()
        self._remote: Any = None

    def open(self) -> None:
        import ray

        if not ray.is_initialized():
            ray.init(address=self.address, log_to_driver=False)
        self._remote = ray.remote(num_cpus=self.cpus_per_group, max_retries=0)(train_handed)
        self._read_capacity()
        self._watcher = threading.Thread(target=self._watch, name="ray-cluster", daemon=True)
        self._watcher.start()

    def close(self) -> None:
        """Server shutdown: the tasks end with this process (Ray's owner rule), so they are
        cancelled, and their sessions left `interrupted` as a local worker's are by a
        shutdown in order: from their last checkpoints, the server's next start resumes
        the people's sessions (`server.live.manager.resumes_after_restart`)."""
        self._closing.set()
        if self._watcher is not None:
            self._watcher.join(10)
        import ray

        with self._lock:
            tasks, self._tasks = dict(self._tasks), {}
        for ref in tasks:
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        with self.factory() as db:
            for task in tasks.values():
                for h in task.handed:
                    set_status(db, h.session_id, Status.interrupted, SHUT_DOWN, token=h.token)
        with contextlib.suppress(Exception):
            ray.shutdown()

    def bind(
        self,
        notify: Callable[[int], None],
        release: Callable[[Seat], None],
        set_slots: Callable[[int], None],
        practised: Callable[[Handed], None] = lambda handed: None,
    ) -> None:
        """The trainer slots' side, called on this event loop (the caller's thread): whom
        an ended task's sessions are told to (`notify`), who frees their seats (`release`),
        who takes the cluster's capacity as the number of trainer slots (`set_slots`), and
        who goes on with a session whose practice ended at its first turn (`practised`)."""
        self._loop = asyncio.get_running_loop()
        self._notify, self._release, self._set_slots = notify, release, set_slots
        self._practised = practised
        if self._capacity:
            set_slots(self._capacity)

    def capacity(self) -> int:
        """Groups the cluster trains at once: the CPUs of its live nodes, `cpus_per_group`
        to a task (read every `CAPACITY_EVERY_S`)."""
        return self._capacity

    def _read_capacity(self) -> None:
        import ray

        self._capacity_read_at = time.monotonic()
        cpus = float(ray.cluster_resources().get("CPU", 0.0))
        capacity = int(cpus // self.cpus_per_group)
        if capacity != self._capacity:
            self._capacity = capacity
            self._on_loop(self._set_slots, capacity)

    def seats(self) -> dict[int, Seat]:
        """The seats of the sessions the cluster trains, by session."""
        with self._lock:
            return dict(self._seats)

    def _on_loop(self, callback: Callable[..., None], *args: Any) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(callback, *args)

    # --- the trainer-slot queue's hand-over ---------------------------------------------
    def take(
        self,
        group: Sequence[HandedHandle],
        handles: MutableMapping[int, Any],
        command_timeout_s: float,
    ) -> None:
        """Train `group` (sessions granted training together) on the cluster: each worker
        checkpoints and exits, then the group goes to a node (the event loop's thread);
        their seats hold their slots until their task ends."""
        with self._lock:
            self._seats.update((h.session_id, h.seat) for h in group)
        for handle in group:
            handle.handing_over = True
            handle.send(Command("handover"))
            self._notify(handle.session_id)
        task = asyncio.get_running_loop().create_task(
            self._hand_over(list(group), handles, command_timeout_s)
        )
        self._handovers.add(task)
        task.add_done_callback(self._handovers.discard)

    async def _hand_over(
        self, group: list[HandedHandle], handles: MutableMapping[int, Any], timeout_s: float
    ) -> None:
        from starlette.concurrency import run_in_threadpool

        for handle in group:
            await run_in_threadpool(join, handle.process, timeout_s)
            if handle.process.is_alive():  # it resumes from its last checkpoint
                log.warning("session %s: its worker did not hand over; killed", handle.session_id)
                with contextlib.suppress(Exception):
                    handle.process.kill()
                await run_in_threadpool(join, handle.process, 5)
        for handle in group:
            if handles.get(handle.session_id) is handle:
                del handles[handle.session_id]
        sent = await run_in_threadpool(self.submit, [Handed(h.session_id, h.token) for h in group])
        for handle in group:
            if handle.session_id not in sent:  # stopped or ended meanwhile: its seat frees
                self._free(handle.session_id)
            self._notify(handle.session_id)

    # --- tasks ----------------------------------------------------------------------------
    def submit(
        self, handed: Sequence[Handed], attempt: int = 1, practice: bool = False
    ) -> list[int]:
        """Send the sessions still `running` (or `paused`) under their tokens to the cluster
        as one task, each under a new token of this process until the task takes it; the
        sessions sent. `practice`: a pool's session, whose task ends at its first turn
        (`WorkerOptions.practice_only`); `bind`'s `practised` then takes it back."""
        ours = self._retoken(handed)
        if ours:
            options = replace(self.options, practice_only=practice)
            ref = self._remote.remote(ours, self.database_url, options)
            with self._lock:
                self._tasks[ref] = _Task(ours, attempt, practice)
        return [h.session_id for h in ours]

    def train(self, handed: Handed, seat: Seat, spec: RunSpec, practice: bool = False) -> None:
        """Train a machine session (a replay, a fitted advisor's or an oracle's run) on the
        cluster from its start, or a pool's session up to its first turn (`practice`), its
        `seat` holding one of the trainer slots until its task ends: the CPU it takes there
        is one the queue's place and wait count, from the episodes (a practice: the steps)
        it has left."""
        seat.practice = practice
        seat.live.receive(self._stored_progress(handed.session_id, spec))
        seat.take_slot(None)
        with self._lock:
            self._seats[handed.session_id] = seat
        if not self.submit([handed], practice=practice):
            self._free(handed.session_id)

    def _stored_progress(self, session_id: int, spec: RunSpec) -> Progress:
        """The session's progress as stored (a resumed one's), else none of its run done."""
        with self.factory() as db:
            stored = db.scalar(select(StudySession.progress).where(StudySession.id == session_id))
        with contextlib.suppress(TypeError):
            return Progress(**(stored or {}))
        episodes = spec.config.episodes
        return Progress("pretraining", 0, 0, episodes, 1.0, 0.0, None, 0, spec.advice_budget)

    def practising(self) -> set[int]:
        """The sessions whose practice a task of this process runs or waits a node for,
        or that a worker of the web process is about to take back."""
        with self._lock:
            tasks = {h.session_id for t in self._tasks.values() if t.practice for h in t.handed}
            return tasks | self._returning

    def returned(self, session_id: int) -> None:
        """The web process is done taking the practised session back."""
        with self._lock:
            self._returning.discard(session_id)

    def take_back(self, handed: Handed) -> str | None:
        """A session whose practice ended, for a worker of this process: a new token, this
        machine its host; None when its row is not under its task's token (stopped, ended or
        deleted meanwhile)."""
        token = uuid.uuid4().hex
        with self.factory() as db:
            result = db.execute(
                update(StudySession)
                .where(
                    StudySession.id == handed.session_id,
                    StudySession.worker_token == handed.token,
                    StudySession.status == Status.running.value,
                )
                .values(
                    worker_token=token,
                    worker_host=HOST,
                    worker_pid=None,
                    heartbeat_at=utcnow(),
                    status_detail="",
                )
            )
            db.commit()
        return token if result.rowcount == 1 else None  # type: ignore[attr-defined]

    def _retoken(self, handed: Sequence[Handed]) -> list[Handed]:
        ours = []
        with self.factory() as db:
            for h in handed:
                token = uuid.uuid4().hex
                result = db.execute(
                    update(StudySession)
                    .where(
                        StudySession.id == h.session_id,
                        StudySession.worker_token == h.token,
                        StudySession.status.in_(
                            [Status.running.value, Status.paused.value, Status.interrupted.value]
                        ),
                    )
                    .values(
                        worker_token=token,
                        worker_pid=None,
                        heartbeat_at=utcnow(),
                        status_detail=WAITING,
                    )
                )
                if result.rowcount == 1:  # type: ignore[attr-defined]
                    ours.append(Handed(h.session_id, token))
            db.commit()
        return ours

    def _watch(self) -> None:
        """The watcher thread: keeps the groups that wait for a node alive, and handles the
        tasks that ended."""
        while not self._closing.wait(WATCH_EVERY_S):
            try:
                self._beat()
                self._collect()
                self._progress()
                if time.monotonic() - self._capacity_read_at >= CAPACITY_EVERY_S:
                    self._read_capacity()
            except Exception:
                log.exception("watching the Ray cluster's tasks failed")

    def _beat(self) -> None:
        with self._lock:
            waiting = [h for t in self._tasks.values() for h in t.handed]
        if not waiting:
            return
        with self.factory() as db:
            for h in waiting:  # a task marks its session alive itself once it runs it
                db.execute(
                    update(StudySession)
                    .where(
                        StudySession.id == h.session_id,
                        StudySession.worker_token == h.token,
                        StudySession.worker_pid.is_(None),
                        StudySession.status_detail == WAITING,
                    )
                    .values(heartbeat_at=utcnow())
                )
            db.commit()

    def _collect(self) -> None:
        import ray

        with self._lock:
            refs = list(self._tasks)
        if not refs:
            return
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
        for ref in ready:
            with self._lock:
                task = self._tasks.get(ref)
            if task is None:  # closing
                return
            try:  # it stays among the tasks until handled: its sessions are never between
                self._handle(task, ref)
            finally:
                with self._lock:
                    self._tasks.pop(ref, None)

    def _handle(self, task: _Task, ref: Any) -> None:
        """An ended task: its sessions' ends, a practice's return, or a start again."""
        import ray

        try:
            statuses = ray.get(ref)
        except ray.exceptions.RayTaskError as error:  # the task's own code raised
            self._fail(task, str(error))
            return
        except ray.exceptions.RayError as error:  # its node or worker died
            self._again(task, error)
            return
        for h in task.handed:
            status = statuses.get(h.session_id)
            if task.practice and status == Status.running.value:
                with self._lock:
                    self._returning.add(h.session_id)
                self._free(h.session_id)  # a worker here waits for its participant
                self._on_loop(self._practised, h)
            elif status is not None:
                self._ended(h.session_id, status)
            else:  # stopped or ended before the task took it: its seat frees
                self._free(h.session_id)
                self._on_loop(self._notify, h.session_id)

    def _again(self, task: _Task, error: Exception) -> None:
        """The task's node (or its worker) died: its sessions start again on another node
        from their last checkpoints, up to `ATTEMPTS` times."""
        log.warning(
            "a Ray task of sessions %s died: %s", [h.session_id for h in task.handed], error
        )
        if task.attempt < ATTEMPTS:
            again = self.submit(task.handed, task.attempt + 1, task.practice)
            log.info("sessions %s start again on the cluster", again)
            for h in task.handed:
                if h.session_id not in again:  # stopped or ended meanwhile
                    self._free(h.session_id)
                    self._on_loop(self._notify, h.session_id)
            return
        detail = f"its node of the Ray cluster died {ATTEMPTS} times; resume it"
        with self.factory() as db:
            for h in task.handed:
                set_status(db, h.session_id, Status.interrupted, detail, token=h.token)
        for h in task.handed:
            self._ended(h.session_id, Status.interrupted.value)

    def _fail(self, task: _Task, detail: str) -> None:
        with self.factory() as db:
            for h in task.handed:
                set_status(db, h.session_id, Status.failed, detail[-4000:], token=h.token)
        for h in task.handed:
            self._ended(h.session_id, Status.failed.value)

    def _ended(self, session_id: int, status: str) -> None:
        self.hub.publish(session_id, "status", StatusChanged(status))
        self._free(session_id)
        self._on_loop(self._notify, session_id)

    def _free(self, session_id: int) -> None:
        """The session left the cluster: its seat's slot frees for the queue."""
        with self._lock:
            seat = self._seats.pop(session_id, None)
        if seat is not None:
            self._on_loop(self._release, seat)

    def _progress(self) -> None:
        """The seats' progress, as their tasks store it: what the queue's wait estimate
        reads of the sessions in the cluster's slots."""
        seats = self.seats()
        if not seats:
            return
        with self.factory() as db:
            rows = db.execute(
                select(StudySession.id, StudySession.progress).where(
                    StudySession.id.in_(list(seats))
                )
            ).all()
        for session_id, stored in rows:
            with contextlib.suppress(TypeError):  # none stored yet, or another shape
                self._on_loop(seats[session_id].live.receive, Progress(**(stored or {})))

    def control(self, session_id: int, status: Status, detail: str = "") -> bool:
        """The researcher's stop (`stopped`), pause (`paused`) or resume (`running`) of a
        session on the cluster, written to its row, where its task reads it within
        `runs.worker.cluster.CONTROL_EVERY_S`; False when no task of this process has it."""
        with self._lock:
            task = next(
                (
                    t
                    for t in self._tasks.values()
                    if any(h.session_id == session_id for h in t.handed)
                ),
                None,
            )
        if task is None:
            return False
        if status != Status.stopped and len(task.handed) > 1:
            raise Conflict(
                f"session {session_id} trains together with other sessions on the cluster "
                "and cannot pause alone; stop it instead (it resumes from its last checkpoint)"
            )
        (token,) = [h.token for h in task.handed if h.session_id == session_id]
        with self.factory() as db:
            return set_status(db, session_id, status, detail, token=token)

    def running(self) -> list[int]:
        """The sessions of the tasks not ended yet."""
        with self._lock:
            return sorted(h.session_id for t in self._tasks.values() for h in t.handed)

    def wait(self, timeout_s: float) -> bool:
        """Wait until every task has ended (True), or `timeout_s` has passed."""
        deadline = time.monotonic() + timeout_s
        while self.running():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.2)
        return True
