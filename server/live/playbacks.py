"""The dashboard's playbacks of recorded episodes, in the web process.

A playback starts a rerun process (`runs.worker.rerun`), keeps what it sends back while
the researcher's page is open, and is closed when the page says it is leaving or after
`idle_s` without a request from it; closing ends the process if it still runs and the
playback's 3-D views. At most `limit` are open at once: a rerun costs a process with
PyBullet, and a researcher's tab should not take a study server's cores from its
participants. Each playback has an unguessable id: its 3-D view's websocket carries it,
as a participant's carries their token, so it works where the dashboard's cookie does
not reach (the view may be on another origin).
"""

from __future__ import annotations

import multiprocessing
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

from sqlalchemy.orm import Session

from runs.worker.rerun import Rerun, RerunFailed, RerunOrder, rerun_main
from study.db.models import StudySession

State = Literal["rerunning", "ready", "failed"]
JOIN_S = 5.0


class TooManyPlaybacks(RuntimeError):
    """The limit of open playbacks is reached."""


@dataclass
class Playback:
    id: str
    session_id: int
    stage: str
    episode: int
    process: multiprocessing.process.BaseProcess | None = None
    state: State = "rerunning"
    detail: str = ""
    rerun: Rerun | None = None
    last_seen: float = field(default_factory=time.monotonic)
    closed: bool = False
    recorded: Any = None
    """What the page shows beside the rerun (`study.services.playback.RecordedEpisode`)."""


class Playbacks:
    """Open playbacks by id; thread-safe (routes run in the thread pool)."""

    def __init__(
        self,
        limit: int,
        idle_s: float,
        on_close: Callable[[Playback], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.limit = limit
        self.idle_s = idle_s
        self._on_close = on_close
        self._clock = clock
        self._lock = threading.Lock()
        self._reaping = threading.Lock()
        """One thread at a time waits for a rerun process: two waiting at once race in
        `os.waitpid`, and the loser can read a reaped process as alive."""
        self._open: dict[str, Playback] = {}
        self._context = multiprocessing.get_context("spawn")
        self._stopping = threading.Event()
        self._sweeper: threading.Thread | None = None

    def open(self) -> None:
        """Sweep idle playbacks now and then, also when no page asks for anything."""
        self._stopping.clear()
        self._sweeper = threading.Thread(
            target=self._sweep_forever, name="playback-sweeper", daemon=True
        )
        self._sweeper.start()

    def _sweep_forever(self) -> None:
        while not self._stopping.wait(max(0.5, min(30.0, self.idle_s / 4))):
            self.sweep()

    def start(
        self, session_id: int, stage: str, episode: int, order: RerunOrder, recorded: Any = None
    ) -> Playback:
        """Start the rerun; raises `TooManyPlaybacks` at the limit."""
        self.sweep()
        with self._lock:
            if len(self._open) >= self.limit:
                raise TooManyPlaybacks(
                    f"{self.limit} playbacks are open already: close one (its page), or wait "
                    f"{self.idle_s:.0f} s for an idle one to end"
                )
            playback = Playback(secrets.token_urlsafe(24), session_id, stage, episode)
            playback.recorded, playback.last_seen = recorded, self._clock()
            self._open[playback.id] = playback
        parent, child = self._context.Pipe(duplex=False)
        process = self._context.Process(
            target=rerun_main,
            args=(child, order),
            name=f"ideeprl-playback-{session_id}",
            daemon=True,
        )
        playback.process = process
        try:
            process.start()
        except Exception:
            self.close(playback.id)
            raise
        child.close()
        threading.Thread(
            target=self._receive, args=(playback, parent), name="playback-reader", daemon=True
        ).start()
        return playback

    def _receive(self, playback: Playback, conn: multiprocessing.connection.Connection) -> None:
        try:
            result = conn.recv()
        except (EOFError, OSError):
            result = RerunFailed("the rerun process ended without a result")
        finally:
            conn.close()
        with self._lock:
            if isinstance(result, Rerun):
                playback.rerun, playback.state = result, "ready"
                if result.mismatch:
                    playback.detail = result.mismatch
            else:
                playback.state, playback.detail = "failed", result.detail
        if playback.process is not None:
            self._end(playback.process, terminate=False)

    def _end(self, process: multiprocessing.process.BaseProcess, terminate: bool) -> None:
        """Wait for the process to end (ending it first if `terminate`); one that ignores
        SIGTERM for `JOIN_S` is killed."""
        with self._reaping:
            if terminate and process.is_alive():
                process.terminate()
                process.join(JOIN_S)
                if process.is_alive():
                    process.kill()
            process.join(JOIN_S)

    def get(self, playback_id: str, touch: bool = True) -> Playback | None:
        """The open playback (its idle time starts again), or None."""
        self.sweep()
        with self._lock:
            playback = self._open.get(playback_id)
            if playback is not None and touch:
                playback.last_seen = self._clock()
            return playback

    def close(self, playback_id: str) -> bool:
        with self._lock:
            playback = self._open.pop(playback_id, None)
        if playback is None:
            return False
        playback.closed = True
        if playback.process is not None:
            self._end(playback.process, terminate=True)
        if self._on_close is not None:
            self._on_close(playback)
        return True

    def sweep(self) -> list[str]:
        """Close the playbacks whose page has not asked for anything for `idle_s`."""
        limit = self._clock() - self.idle_s
        with self._lock:
            idle = [p.id for p in self._open.values() if p.last_seen < limit]
        for playback_id in idle:
            self.close(playback_id)
        return idle

    def close_sessions(self, gone: Callable[[int], bool]) -> list[str]:
        """Close the playbacks of the sessions `gone(session_id)` says were deleted: what
        they hold of a participant goes with the participant's data."""
        with self._lock:
            chosen = [p.id for p in self._open.values() if gone(p.session_id)]
        for playback_id in chosen:
            self.close(playback_id)
        return chosen

    def close_deleted(self, db: Session) -> list[str]:
        """After a deletion: the playbacks of sessions that no longer exist end now."""
        return self.close_sessions(lambda session_id: db.get(StudySession, session_id) is None)

    def open_ids(self) -> list[str]:
        with self._lock:
            return list(self._open)

    def close_all(self) -> None:
        """Server shutdown: every playback ends, and the sweeper."""
        self._stopping.set()
        if self._sweeper is not None:
            self._sweeper.join(JOIN_S)
        for playback_id in self.open_ids():
            self.close(playback_id)
