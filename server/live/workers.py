"""The web process's worker processes: how each starts, how its pipe is read, how it is
killed.

Session workers are forked from a fork server that has loaded torch and PyBullet once
(`worker_context`). Each pipe has a reader thread that publishes what its worker says on
the hub and hands each message on (`deliver`), and says when the worker has exited
(`exited`): what a message or an exit means for the session is the caller's.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing import forkserver
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

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
)
from runs.worker.population import population_main
from runs.worker.worker import WorkerOptions, worker_context, worker_main
from server.live.hub import Hub
from server.live.reaping import join
from server.live.session import LiveSession
from server.live.trainers import Seat

HUB_KINDS: dict[type, str] = {
    Progress: "progress",
    AdviceRequest: "advice_request",
    AdviceResult: "advice_result",
    EpisodeDone: "episode",
    SceneReset: "scene_reset",
    SceneStep: "scene_step",
    StatusChanged: "status",
}


@dataclass
class WorkerHandle:
    session_id: int
    token: str
    process: Any
    conn: Connection
    live: LiveSession
    seat: Seat
    """Its standing with the trainer slots."""
    killed: bool = False
    """The web process killed its worker (`SessionManager._kill`), which records the status."""
    handing_over: bool = False
    """Its worker checkpoints and exits, for its population's worker to go on (this handle
    is then replaced by one on the population's worker)."""
    in_population: bool = False
    """It trains in a population's worker (`process` and `conn` are the population's)."""
    started: float = field(default_factory=time.monotonic)
    reported: bool = False
    """The worker has said something: it is past its start (imports, resuming)."""
    stopping: bool = False
    """The researcher asked it to stop: if it hangs, it ends `stopped`, not `interrupted`."""
    send_lock: threading.Lock = field(default_factory=threading.Lock)

    def send(self, message: Any) -> bool:
        with self.send_lock:
            try:
                self.conn.send(message)
                return True
            except (BrokenPipeError, EOFError, OSError):
                return False


Deliver = Callable[[WorkerHandle, Any], None]
"""Called on the reader thread with each message of a session's worker."""
Exited = Callable[[WorkerHandle, "int | None"], None]
"""Called on the reader thread once a session's worker has exited, with its exit code."""


class Workers:
    def __init__(self, database_url: str, hub: Hub, deliver: Deliver, exited: Exited) -> None:
        self.database_url = database_url
        self.hub = hub
        self._deliver = deliver
        self._exited = exited
        self._context = worker_context()

    def warm(self) -> None:
        """Load the fork server before the first participant arrives, not while they wait."""
        if isinstance(self._context, multiprocessing.context.ForkServerContext):
            threading.Thread(target=forkserver.ensure_running, daemon=True).start()

    def start(
        self, session_id: int, options: WorkerOptions, token: str
    ) -> tuple[BaseProcess, Connection]:
        """A session's worker, started; its process and the web process's end of its pipe."""
        parent, child = self._context.Pipe(duplex=True)
        process = self._context.Process(
            target=worker_main,
            args=(session_id, self.database_url, options, token, child),
            name=f"ideeprl-session-{session_id}",
            daemon=True,
        )
        process.start()
        child.close()
        return process, parent

    def start_population(
        self, ids: list[int], tokens: dict[int, str], options: WorkerOptions
    ) -> tuple[BaseProcess, Connection]:
        """One worker that trains the sessions `ids` together, started."""
        parent, child = self._context.Pipe(duplex=True)
        process = self._context.Process(
            target=population_main,
            args=(ids, tokens, self.database_url, options, child),
            name=f"ideeprl-population-{'-'.join(map(str, ids))}",
            daemon=True,
        )
        process.start()
        child.close()
        return process, parent

    def read(self, handle: WorkerHandle) -> None:
        """Read the session's worker on a thread of its own, until its pipe closes."""
        threading.Thread(
            target=self._read,
            args=(handle,),
            name=f"session-{handle.session_id}-reader",
            daemon=True,
        ).start()

    def read_population(
        self, conn: Connection, process: Any, members: dict[int, WorkerHandle]
    ) -> None:
        """Read a population's worker on a thread of its own: each message to its
        session's handle."""
        threading.Thread(
            target=self._read_population,
            args=(conn, process, members),
            name=f"population-{'-'.join(map(str, members))}-reader",
            daemon=True,
        ).start()

    @staticmethod
    def kill(handle: WorkerHandle) -> None:
        """SIGKILL (it works on a stopped process too), and wait for it to be gone."""
        with contextlib.suppress(Exception):
            handle.process.kill()
        join(handle.process, 5)

    @staticmethod
    def shut_down(handles: list[WorkerHandle]) -> None:
        """Ask each worker to checkpoint and exit; terminate those still running after a
        minute."""
        for handle in handles:
            handle.send(Command("shutdown"))
        for handle in handles:
            join(handle.process, 60)
            if handle.process.is_alive():
                handle.process.terminate()

    def _read(self, handle: WorkerHandle) -> None:
        while True:
            try:
                message = handle.conn.recv()
            except (EOFError, OSError):
                break
            kind = HUB_KINDS.get(type(message))
            if kind is not None:
                self.hub.publish(handle.session_id, kind, message)
            self._deliver(handle, message)
        self._exited(handle, join(handle.process, 10))

    def _read_population(
        self, conn: Connection, process: Any, members: dict[int, WorkerHandle]
    ) -> None:
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
            self._deliver(handle, message.message)
        code = join(process, 10)
        for handle in members.values():
            self._exited(handle, code)
