"""Pools of pretrained sessions, so an arrival's first turn never waits for the robot's
random practice.

Each condition of an online study still short of its target keeps up to its design's `pool`
sessions made ahead of arrivals (`study.services.assignment.pool_gaps`), all pools together
within the server's `pool_limit`. A pooled session is made with its condition's run and the
study's next number added to its seed (both fixed and recorded then), and started at once:
it practises, then waits at its first turn with its idle limit off. The arrival that the
randomization gives its condition takes the oldest ready one (`assignment.arrive`); the
idle limit runs from then (`SessionManager.assign`), and the pool is topped up again.
At most `practising` pooled sessions practise at once (one fewer than the cores by
default): a practice takes a core for several seconds, and the participants advising
meanwhile keep the rest. With a Ray cluster the practice runs there, and the session comes
back to a worker of this machine at its first turn (`SessionManager.start`).
A pooled session whose worker stopped (a restart, a failure) holds nobody's data: it is
deleted and made again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from pathlib import Path

from starlette.concurrency import run_in_threadpool

from learner.fields import FieldError
from server.live.manager import SessionManager
from study.db.models import Status
from study.services import assignment, storage
from study.services.errors import Conflict, ServiceError

log = logging.getLogger(__name__)


class Pools:
    def __init__(
        self,
        manager: SessionManager,
        limit: int,
        every_s: float,
        data_dir: Path,
        threads: int | None = None,
        practising: int = 1,
    ) -> None:
        assert practising >= 1
        self.manager = manager
        self.limit = limit
        self.practising_limit = practising
        self._started: set[int] = set()
        self.every_s = every_s
        self.data_dir = data_dir
        self.threads = threads
        self._task: asyncio.Task[None] | None = None

    def open(self) -> None:
        if self.limit > 0:
            self._task = asyncio.create_task(self._forever())

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    async def _forever(self) -> None:
        while True:
            try:
                await self.top_up()
            except Exception:
                log.exception("topping up the pools failed")
            await asyncio.sleep(self.every_s)

    async def top_up(self) -> list[int]:
        """Delete pooled sessions that stopped, make and start what the pools lack; the ids
        of the sessions started."""
        await run_in_threadpool(self._clear_stale)
        room = self.practising_limit - self.practising()
        if room <= 0:
            return []
        made = await run_in_threadpool(self._make, room)
        for session_id in made:
            with contextlib.suppress(Conflict):
                await self.manager.start(session_id, pooled=True)
                self._started.add(session_id)
        return made

    def practising(self) -> int:
        """Pooled sessions this server started that are not at their first turn yet."""
        for session_id in list(self._started):
            if self.manager.practising_elsewhere(session_id):  # on the Ray cluster
                continue
            live = self.manager.live(session_id)
            if live is None or live.status != Status.running.value or live.at_first_turn:
                self._started.discard(session_id)
        return len(self._started)

    def _clear_stale(self) -> None:
        with self.manager.factory() as db:
            for session_id in assignment.stale_pooled(db):
                storage.delete_session(
                    db, self.data_dir, session_id, False, self.manager.options.data_dir
                )

    def _make(self, at_most: int) -> list[int]:
        made: list[int] = []
        with assignment.ARRIVALS, self.manager.factory() as db:
            for gap in assignment.pool_gaps(db, self.limit):
                for _ in range(min(gap.missing, at_most - len(made))):
                    try:
                        made.append(
                            assignment.make_pooled(
                                db,
                                gap.study_id,
                                gap.condition,
                                self.data_dir,
                                self.threads,
                            )
                        )
                    except (ServiceError, FieldError) as error:  # a run this machine refuses
                        log.warning("pool of study %s: %s", gap.study_id, error)
                        db.rollback()
                        break
        return made
