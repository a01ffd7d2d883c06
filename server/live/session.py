"""One running session's advice turn as its participant's page sees it: the pending
request, whether the robot moves, the advice given, recent history, the live status.

The routes read a `LiveSession`; only its own methods write it, each on the event loop's
thread, and each change that the page shows gives the session a new version (`Changes`),
which wakes the participant's long poll.

Every session has a version, live or not (a finished session's page polls too); the
versions are drawn from one counter that starts at the clock, so a page that outlives a
restart never sees one go back.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
from collections import deque
from dataclasses import dataclass, replace

from runs.worker.messages import AdviceRequest, AdviceResult, Progress, StatusChanged
from study.db.models import Status

HISTORY = 10
COALESCE_S = 0.05


class Changes:
    """Each session's version: what the participant's long poll waits on."""

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


@dataclass
class HistoryEntry:
    advice_index: int
    action: int
    global_step: int
    """The step advised: the robot's own moves since are counted from it."""
    reward: float | None = None


class LiveSession:
    def __init__(
        self,
        session_id: int,
        advice_budget: int,
        answered: list[tuple[int, int, int]],
        changes: Changes,
        steps_before_first_turn: int = 0,
        human: bool = False,
        pooled: bool = False,
    ) -> None:
        """`answered`: the advice stored before its worker started (index, action, step)."""
        self.session_id = session_id
        self.advice_budget = advice_budget
        self.given: dict[int, int] = {index: action for index, action, _ in answered}
        self.history: deque[HistoryEntry] = deque(
            (HistoryEntry(*row) for row in answered), maxlen=HISTORY
        )
        self.steps_before_first_turn = steps_before_first_turn
        """Random pretraining steps before the first advice (what the page's progress
        counts)."""
        self.human = human
        """A person advises it."""
        self.pooled = pooled
        """It waits in its condition's pool (the pools keep their own count)."""
        self.status: str = Status.running.value
        self.progress: Progress | None = None
        self.request: AdviceRequest | None = None
        self.request_arrived = 0.0
        self.shown_at: float | None = None
        self.moving = False
        self.ready = False
        """The participant consented and finished the induction (human sessions)."""
        self.last_reward: float | None = None
        self.advice_lock = asyncio.Lock()
        """Held while one advice is checked, stored and forwarded."""
        self._changes = changes

    @property
    def version(self) -> int:
        return self._changes.version(self.session_id)

    @property
    def at_first_turn(self) -> bool:
        """Its random pretraining is over: it asks for advice, or waits for its participant
        to be ready for it."""
        progress = self.progress
        done = progress.global_step if progress is not None else 0
        waiting = progress is not None and progress.waiting_for_participant
        return self.request is not None or waiting or done >= self.steps_before_first_turn

    def receive(self, message: object) -> None:
        """What its worker said, on the event loop's thread."""
        if isinstance(message, Progress):
            self.progress = message
            return
        if isinstance(message, AdviceRequest):
            self.request = message
            self.request_arrived = time.monotonic()
            self.shown_at = None
            self.moving = False
        elif isinstance(message, AdviceResult):
            self.moving = False
            self.last_reward = message.reward
            for entry in self.history:
                if entry.advice_index == message.advice_index:
                    entry.reward = message.reward
            self._changes.notify_soon(self.session_id)
            return
        elif isinstance(message, StatusChanged):
            self.status = message.status
        else:
            return
        self._changes.notify(self.session_id)

    def show(self) -> AdviceRequest | None:
        """The request the page shows (none before the participant is ready); showing one
        the running session waits on starts its response-time clock."""
        request = self.request if self.ready else None
        if request is not None and self.status == Status.running and self.shown_at is None:
            self.shown_at = time.monotonic()
        return request

    def response_time_s(self, now: float) -> float:
        """Seconds the pending request has waited, from when it was shown (else arrived)."""
        return now - (self.shown_at or self.request_arrived)

    def take_advice(self, advice: HistoryEntry) -> None:
        """The participant's advice for the pending request, stored: the robot moves."""
        self.given[advice.advice_index] = advice.action
        self.request = None
        self.moving = True
        self.history.append(advice)
        self._changes.notify(self.session_id)

    def take_rating(self, rated: HistoryEntry, reward: float | None) -> None:
        """The rating of the learner's own move for the pending request, stored or lapsed:
        the move is already made, the learner goes on."""
        self.given[rated.advice_index] = rated.action
        self.request = None
        self.history.append(rated)
        self.last_reward = reward
        self._changes.notify(self.session_id)

    def set_ready(self) -> None:
        """The participant consented and finished the induction: advice may be asked."""
        self.ready = True
        self._changes.notify(self.session_id)

    def set_status(self, status: str) -> None:
        """The web process decided the status (it killed the worker) and records it."""
        self.status = status

    def handed_over(self) -> LiveSession:
        """The session as it goes on training in a population's worker: what it has been
        given and shown so far, no request pending."""
        assert self.progress is not None
        moved = LiveSession(
            self.session_id,
            self.advice_budget,
            [],
            self._changes,
            steps_before_first_turn=self.steps_before_first_turn,
        )
        moved.given = self.given
        moved.history = self.history
        moved.progress = replace(self.progress, queued=False)
        moved.last_reward = self.last_reward
        moved.ready = self.ready
        return moved
