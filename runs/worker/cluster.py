"""Sessions trained as a Ray task on any node of a cluster, after the web process handed
them over (`server.live.cluster`).

The database is the only channel: the task writes each session's records, progress,
checkpoints and status there as a local worker does, and reads the researcher's control
from the session's row (`DatabaseChannel`). A group of more than one trains as a
population (`runs.worker.population`), one alone as its own run; either way each session
resumes from its last checkpoint, so a task that dies on one node is started again on
another from there, with the records an uninterrupted run would have.
"""

from __future__ import annotations

import os
import socket
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection
from pathlib import Path
from typing import cast

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from runs.worker.messages import Command
from runs.worker.population import run_population
from runs.worker.worker import WorkerOptions, run_session
from study.db.engine import make_engine, make_session_factory
from study.db.models import Status, StudySession

CONTROL_EVERY_S = 1.0
"""How often a task reads its sessions' control from the database while it trains."""
TRAINS_ON = "training on "
"""How a session's status detail names the node it trains on."""
STORAGE_ROOT_VARIABLE = "IDEEPRL_STORAGE_ROOT"


@dataclass(frozen=True)
class Handed:
    """A session handed to the cluster, `running` (or `paused`) under `token`."""

    session_id: int
    token: str


class DatabaseChannel:
    """A `WorkerLink`'s channel for sessions whose web process is on another machine: what
    they would send it is in the database already (progress, records, status), and the
    commands come from their rows. Their advice is over, so they are ready and may train;
    a row set `stopped` stops its session (checkpointed), `paused` pauses a session that
    trains alone and `running` again resumes it (a population does not pause, as in a
    local slot)."""

    def __init__(
        self, factory: sessionmaker[Session], handed: Sequence[Handed], population: bool
    ) -> None:
        self._factory = factory
        self._tokens = {h.session_id: h.token for h in handed}
        self._population = population
        self._pending: deque[Command] = deque([Command("ready"), Command("train")])
        self._paused = False
        self._stopping: set[int] = set()
        self._read_at = 0.0

    def send(self, message: object) -> None:
        """Nothing listens: the run writes what matters to the database itself."""

    def poll(self, timeout: float = 0.0) -> bool:
        if not self._pending:
            if timeout > 0:
                time.sleep(min(timeout, CONTROL_EVERY_S))
            if time.monotonic() - self._read_at >= CONTROL_EVERY_S:
                self._read()
        return bool(self._pending)

    def recv(self) -> object:
        return self._pending.popleft()

    def _read(self) -> None:
        self._read_at = time.monotonic()
        with self._factory() as db:
            rows = db.execute(
                select(StudySession.id, StudySession.status, StudySession.status_detail).where(
                    StudySession.id.in_(list(self._tokens)),
                    StudySession.worker_token.in_(list(self._tokens.values())),
                )
            ).all()
        for session_id, status, detail in rows:
            if status == Status.stopped and session_id not in self._stopping:
                self._stopping.add(session_id)
                named = session_id if self._population else None
                self._pending.append(Command("stop", reason=detail, session_id=named))
            elif not self._population and (status == Status.paused) != self._paused:
                self._paused = status == Status.paused
                self._pending.append(Command("pause" if self._paused else "resume"))


def node_name() -> str:
    """This node as the dashboard names where a session trains."""
    import ray

    node = ray.get_runtime_context().get_node_id()
    return f"{socket.gethostname()}, Ray node {node[:12]}"


def node_storage_root(web: Path) -> Path:
    """The storage root as this node mounts it: `IDEEPRL_STORAGE_ROOT` in the environment
    `ray start` ran in here, else the path the web server mounts it at (`web`). Checkpoint
    paths are stored relative to it, so each node may mount the shared folder anywhere."""
    here = os.environ.get(STORAGE_ROOT_VARIABLE)
    return Path(here) if here else web


def adopt(factory: sessionmaker[Session], handed: Sequence[Handed], node: str) -> list[Handed]:
    """The sessions still handed to this task (their token unchanged: not stopped, ended or
    taken back meanwhile), marked as training on `node`."""
    adopted = []
    with factory() as db:
        for h in handed:
            result = db.execute(
                update(StudySession)
                .where(
                    StudySession.id == h.session_id,
                    StudySession.worker_token == h.token,
                    StudySession.status.in_([Status.running.value, Status.paused.value]),
                )
                .values(worker_host=node[:255], status_detail=f"{TRAINS_ON}{node}")
            )
            if result.rowcount == 1:  # type: ignore[attr-defined]
                adopted.append(h)
        db.commit()
    return adopted


def train_handed(
    handed: Sequence[Handed], database_url: str, options: WorkerOptions
) -> dict[int, str]:
    """The Ray task: train the handed sessions to their end on this node (a pool's session
    with `options.practice_only` to its first turn, still `running`); each one's status
    then (as `run_session` gives it)."""
    factory = make_session_factory(make_engine(database_url))
    adopted = adopt(factory, handed, node_name())
    if not adopted:
        return {}
    # the node's task is its trainer slot: no lower priority, no local queue
    options = replace(
        options,
        data_dir=node_storage_root(options.data_dir),
        nice=0,
        idle=False,
        train_nice=0,
        train_idle=False,
        pooled=False,
    )
    channel = cast(Connection, DatabaseChannel(factory, adopted, population=len(adopted) > 1))
    tokens = {h.session_id: h.token for h in adopted}
    if len(adopted) > 1:
        return run_population(list(tokens), database_url, options, channel, tokens=tokens)
    (h,) = adopted
    status = run_session(h.session_id, database_url, options, worker_token=h.token, conn=channel)
    return {h.session_id: status}
