"""Which version of each session's participant-visible state is the newest: what the
participant's long poll waits on.

Every session has a version, live or not (a finished session's page polls too); the
versions are drawn from one counter that starts at the clock, so a page that outlives a
restart never sees one go back.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time

COALESCE_S = 0.05


class Changes:
    def __init__(self) -> None:
        self._versions = itertools.count(int(time.time() * 1000))
        self._version: dict[int, int] = {}
        self._changed: dict[int, asyncio.Event] = {}

    def version(self, session_id: int) -> int:
        if session_id not in self._version:
            self._version[session_id] = next(self._versions)
        return self._version[session_id]

    async def wait(self, session_id: int, after: int, timeout: float) -> None:
        """Return when the session's participant-visible state is newer than `after`."""
        if self.version(session_id) > after:
            return
        event = self._changed.setdefault(session_id, asyncio.Event())
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(event.wait(), timeout)

    def notify(self, session_id: int) -> None:
        self._version[session_id] = next(self._versions)
        event = self._changed.pop(session_id, None)
        if event is not None:
            event.set()

    def notify_soon(self, session_id: int) -> None:
        """Notify unless something else does first: the next advice request usually follows
        an advice's result within milliseconds, and one wake-up then serves both. On the
        event loop's thread."""
        version = self.version(session_id)

        def later() -> None:
            if self.version(session_id) == version:
                self.notify(session_id)

        asyncio.get_running_loop().call_later(COALESCE_S, later)
