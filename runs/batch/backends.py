"""Where a batch's runs execute: worker processes on this machine, or tasks on Ray.

A backend is handed groups of runs: a group of one is `runs.worker.worker.run_session`
in a process of its own, a larger group a population (`runs.worker.population`: runs
sharing one learner configuration, trained together in one process); either way each run
writes its own session in the shared database. A backend only starts groups, says which
runs have ended, and stops the rest so they can resume later.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import os
import signal
from dataclasses import dataclass, field, replace
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Any, Protocol

from learner.machine import usable_cores
from runs.worker.messages import Command
from runs.worker.population import NOT_RUN, run_population
from runs.worker.priority import lower_priority
from runs.worker.worker import WORKER_PRELOAD, WorkerOptions, run_session, worker_context

ROOT = Path(__file__).absolute().parents[2]
STOP_WAIT_S = 60.0
KNOWN_ENDINGS = ("finished", "failed", "stopped", "interrupted", "abandoned", "lost")
"""What `run_session` returns; anything else is a problem to report."""


class Backend(Protocol):
    capacity: int
    """Groups it executes at once (worker processes, or Ray tasks)."""

    def start(self, session_ids: tuple[int, ...]) -> None:
        """Run the sessions to their end, together when more than one (each is claimed:
        created starts, interrupted resumes)."""

    def busy(self) -> int:
        """Groups running."""

    def ended(self) -> dict[int, str]:
        """Sessions whose run has ended since the last call, with a problem ("" if none)."""

    def running(self) -> list[int]: ...

    def stop(self) -> None:
        """Stop every run so it can resume (checkpointed where possible); then close."""

    def close(self) -> None: ...


@dataclass(frozen=True)
class RunRequest:
    """Runner -> idle worker: run these sessions to their end (more than one: together, as a
    population)."""

    session_ids: tuple[int, ...]


@dataclass(frozen=True)
class RunEnded:
    """Worker -> runner: the session's run returned (`status` as `run_session` gives it)."""

    session_id: int
    status: str


def _worker_loop(database_url: str, options: WorkerOptions, conn: Connection) -> None:
    """A worker process: runs one session after another, until told to stop or orphaned.

    Kept alive between runs because starting one (torch, PyBullet) takes seconds."""
    # Ctrl-C reaches the whole process group; the runner stops its workers in order.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s batch worker %(message)s")
    if options.nice or options.idle:
        lower_priority(options.nice, idle=options.idle)  # once, not again at every run
        options = replace(options, nice=0, idle=False)
    parent = os.getppid()
    while os.getppid() == parent:
        try:
            if not conn.poll(1.0):
                continue
            message = conn.recv()
        except (EOFError, OSError):
            return
        if not isinstance(message, RunRequest):
            return  # Command("shutdown") between runs
        try:
            statuses = run_group(message.session_ids, database_url, options, conn)
        except OSError:
            return
        gc.collect()  # the last runs' memory and PyBullet worlds, before the next
        if "interrupted" in statuses.values():  # shut down by the runner, or the runner died
            return


def run_group(
    session_ids: tuple[int, ...],
    database_url: str,
    options: WorkerOptions,
    conn: Connection | None = None,
) -> dict[int, str]:
    """Run a group of sessions here (one alone, more as a population), telling `conn` as
    each ends; their final statuses."""
    if len(session_ids) > 1:

        def tell(session_id: int, status: str) -> None:
            if conn is not None:
                with contextlib.suppress(OSError):  # a runner gone: the link notices it
                    conn.send(RunEnded(session_id, status))

        return run_population(session_ids, database_url, options, conn, tell)
    (session_id,) = session_ids
    try:
        status = run_session(session_id, database_url, options, conn=conn)
    except Exception as error:  # could not even claim it (e.g. someone else runs it)
        status = f"{NOT_RUN}{error}"
    if conn is not None:
        conn.send(RunEnded(session_id, status))
    return {session_id: status}


@dataclass
class _Worker:
    process: BaseProcess
    conn: Connection
    session_ids: set[int] = field(default_factory=set)
    """The runs it has not reported ended yet; empty: idle."""


class LocalBackend:
    """Worker processes on this machine (forked from a fork server that has loaded torch,
    PyBullet and this module, `worker_context`: each owns its PyBullet and torch), each
    running one session after another.

    Each worker has a pipe: the runner hands it sessions and asks it to shut down through
    it (the running session checkpoints and becomes `interrupted`); a worker whose runner
    died notices, and does the same."""

    def __init__(self, database_url: str, options: WorkerOptions, workers: int) -> None:
        self.database_url = database_url
        self.options = options
        self.capacity = workers
        self._context = worker_context((*WORKER_PRELOAD, __name__))
        self._workers: list[_Worker] = []
        self._ended: dict[int, str] = {}

    def _spawn(self) -> _Worker:
        parent, child = self._context.Pipe(duplex=True)
        process = self._context.Process(
            target=_worker_loop,
            args=(self.database_url, self.options, child),
            name="ideeprl-batch-worker",
            daemon=True,
        )
        process.start()
        child.close()
        worker = _Worker(process, parent)
        self._workers.append(worker)
        return worker

    def start(self, session_ids: tuple[int, ...]) -> None:
        idle = [w for w in self._workers if not w.session_ids and w.process.is_alive()]
        worker = idle[0] if idle else self._spawn()
        worker.conn.send(RunRequest(session_ids))
        worker.session_ids = set(session_ids)

    def busy(self) -> int:
        return sum(bool(w.session_ids) for w in self._workers)

    def _read(self, worker: _Worker) -> None:
        """Everything the worker has said; the runner reads progress from the database, but
        a pipe left full would block the worker."""
        with contextlib.suppress(EOFError, OSError):
            while worker.conn.poll():
                message = worker.conn.recv()
                if isinstance(message, RunEnded) and message.session_id in worker.session_ids:
                    problem = "" if message.status in KNOWN_ENDINGS else message.status
                    self._ended[message.session_id] = problem
                    worker.session_ids.discard(message.session_id)

    def ended(self) -> dict[int, str]:
        for worker in list(self._workers):
            self._read(worker)
            if not worker.process.is_alive():
                code = worker.process.exitcode
                for session_id in worker.session_ids:
                    self._ended[session_id] = f"its worker exited with code {code}"
                worker.conn.close()
                self._workers.remove(worker)
        ended, self._ended = self._ended, {}
        return ended

    def running(self) -> list[int]:
        return [session_id for w in self._workers for session_id in sorted(w.session_ids)]

    def stop(self) -> None:
        for worker in self._workers:
            with contextlib.suppress(OSError):
                worker.conn.send(Command("shutdown"))
        for worker in self._workers:
            worker.process.join(STOP_WAIT_S)
            if worker.process.is_alive():
                worker.process.terminate()
                worker.process.join(5)
        self.close()

    def close(self) -> None:
        """Idle workers exit when their pipe closes; busy ones checkpoint first."""
        for worker in self._workers:
            worker.conn.close()
        for worker in self._workers:
            worker.process.join(STOP_WAIT_S)
        self._workers.clear()


def _run_on_ray(
    session_ids: tuple[int, ...], database_url: str, options: WorkerOptions
) -> dict[int, str]:
    return run_group(session_ids, database_url, options)


class RayBackend:
    """Tasks on a Ray cluster (`address`), or on a local Ray instance started here.

    Every node must reach the database (PostgreSQL for a cluster; a SQLite file only on
    this machine) and the data folder (checkpoints, the advisor's), and have this package
    installed. A group (a population) is one task. A stopped run's task is cancelled: its
    sessions resume from their last periodic checkpoints."""

    def __init__(
        self,
        database_url: str,
        options: WorkerOptions,
        address: str | None,
        workers: int | None,
        cpus_per_run: int,
    ) -> None:
        try:
            import ray
        except ImportError:
            raise RuntimeError(
                "the ray backend needs Ray: pip install 'ideeprl[ray]' (or pip install ray)"
            ) from None
        self._ray = ray
        self.database_url = database_url
        self.options = options
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            # A local instance: its workers import this package from this checkout.
            path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
            ray.init(
                num_cpus=(workers or usable_cores()) * cpus_per_run,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env={"env_vars": {"PYTHONPATH": path}},
            )
        cluster_cpus = int(ray.cluster_resources().get("CPU", 1))
        self.capacity = workers or max(1, cluster_cpus // cpus_per_run)
        self._remote = ray.remote(num_cpus=cpus_per_run, max_retries=0)(_run_on_ray)
        self._tasks: dict[Any, tuple[int, ...]] = {}

    def start(self, session_ids: tuple[int, ...]) -> None:
        ref = self._remote.remote(session_ids, self.database_url, self.options)
        self._tasks[ref] = session_ids

    def busy(self) -> int:
        return len(self._tasks)

    def ended(self) -> dict[int, str]:
        if not self._tasks:
            return {}
        ready, _ = self._ray.wait(list(self._tasks), num_returns=len(self._tasks), timeout=0)
        done = {}
        for ref in ready:
            session_ids = self._tasks.pop(ref)
            try:
                statuses = self._ray.get(ref)
                for session_id, status in statuses.items():
                    done[session_id] = "" if status in KNOWN_ENDINGS else status
            except Exception as error:
                done.update({s: f"its Ray task failed: {error}" for s in session_ids})
        return done

    def running(self) -> list[int]:
        return [session_id for group in self._tasks.values() for session_id in group]

    def stop(self) -> None:
        for ref in self._tasks:
            self._ray.cancel(ref, force=True)
        self._tasks.clear()
        self.close()

    def close(self) -> None:
        if self._ray.is_initialized():
            with contextlib.suppress(Exception):
                self._ray.shutdown()
