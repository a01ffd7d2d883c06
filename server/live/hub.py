"""An in-process publish/subscribe hub: per-session events from the workers, for viewers.

The web process's channel readers publish every message a worker sends; a viewer (the
viser scene of the participant page, a dashboard plot, a test) subscribes per session.
Callbacks run on the publishing thread and must only hand work on; `stream()` gives an
asyncio iterator instead. A new subscriber first receives the latest event of each
`REPLAYED` kind, so a viewer that joins late can draw the scene at once. The hub tells
listeners when a session gains its first or loses its last subscriber, so workers only
send scene events while somebody watches.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import threading
import time
from collections.abc import AsyncIterator, Callable, Collection
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)

KINDS = (
    "status",
    "progress",
    "advice_request",
    "advice_given",
    "rating_given",
    "advice_result",
    "episode",
    "scene_reset",
    "scene_step",
)
REPLAYED = ("status", "progress", "scene_reset", "scene_step", "advice_request")


@dataclass(frozen=True)
class HubEvent:
    session_id: int
    """The session the event belongs to."""
    kind: str
    """One of `KINDS`."""
    payload: Any
    """The worker's message (`runs.worker.messages`), or a dict for `advice_given` and
    `rating_given`."""
    seq: int
    """Hub-wide sequence number: later events have larger numbers."""
    time: float
    """`time.monotonic()` when published."""


Callback = Callable[[HubEvent], object]
"""Called with each event; what it returns is ignored."""


class Subscription:
    def __init__(self, hub: Hub, session_id: int, callback: Callback, kinds: frozenset[str]):
        self._hub, self.session_id, self.callback, self.kinds = hub, session_id, callback, kinds

    def close(self) -> None:
        self._hub._unsubscribe(self)

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


class Hub:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._subscriptions: dict[int, list[Subscription]] = {}
        self._latest: dict[tuple[int, str], HubEvent] = {}
        self._seq = itertools.count(1)
        self._watch_listeners: list[Callable[[int, bool], None]] = []

    def publish(self, session_id: int, kind: str, payload: Any) -> HubEvent:
        assert kind in KINDS, kind
        with self._lock:
            event = HubEvent(session_id, kind, payload, next(self._seq), time.monotonic())
            if kind in REPLAYED:
                self._latest[(session_id, kind)] = event
            if kind == "scene_reset":
                self._latest.pop((session_id, "scene_step"), None)
            subscribers = list(self._subscriptions.get(session_id, ()))
        for subscription in subscribers:
            if kind in subscription.kinds:
                self._deliver(subscription, event)
        return event

    def subscribe(
        self, session_id: int, callback: Callback, kinds: Collection[str] = KINDS
    ) -> Subscription:
        unknown = set(kinds) - set(KINDS)
        assert not unknown, f"unknown event kinds {sorted(unknown)}"
        subscription = Subscription(self, session_id, callback, frozenset(kinds))
        with self._lock:
            subscribers = self._subscriptions.setdefault(session_id, [])
            subscribers.append(subscription)
            first = len(subscribers) == 1
            replay = sorted(
                (e for (sid, kind), e in self._latest.items() if sid == session_id),
                key=lambda e: e.seq,
            )
        for event in replay:
            if event.kind in subscription.kinds:
                self._deliver(subscription, event)
        if first:
            self._notify_watchers(session_id, True)
        return subscription

    def latest(self, session_id: int, kind: str) -> HubEvent | None:
        with self._lock:
            return self._latest.get((session_id, kind))

    def watchers(self, session_id: int) -> int:
        with self._lock:
            return len(self._subscriptions.get(session_id, ()))

    def on_watchers_changed(self, listener: Callable[[int, bool], None]) -> None:
        """`listener(session_id, watched)` when the first subscriber comes or the last goes."""
        self._watch_listeners.append(listener)

    async def stream(
        self, session_id: int, kinds: Collection[str] = KINDS
    ) -> AsyncIterator[HubEvent]:
        """The session's events as an async iterator (for websockets, SSE, tests)."""
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[HubEvent] = asyncio.Queue()
        with self.subscribe(
            session_id, lambda e: loop.call_soon_threadsafe(queue.put_nowait, e), kinds
        ):
            while True:
                yield await queue.get()

    def _unsubscribe(self, subscription: Subscription) -> None:
        with self._lock:
            subscribers = self._subscriptions.get(subscription.session_id, [])
            if subscription not in subscribers:
                return
            subscribers.remove(subscription)
            last = not subscribers
        if last:
            self._notify_watchers(subscription.session_id, False)

    def _notify_watchers(self, session_id: int, watched: bool) -> None:
        for listener in self._watch_listeners:
            try:
                listener(session_id, watched)
            except Exception:
                log.exception("hub watch listener failed")

    @staticmethod
    def _deliver(subscription: Subscription, event: HubEvent) -> None:
        try:
            subscription.callback(event)
        except Exception:
            log.exception("hub subscriber of session %s failed", subscription.session_id)
