"""Arrival limits of the public study links: a sliding window of events per key.

The link is public, and each arrival may start a worker of several hundred MB; one window
per study (sized to its capacity) and one per client address (generous: people behind one
address arrive together) keep a flood from filling the machine.
"""

from __future__ import annotations

import threading
import time
from collections import deque

MAX_KEYS = 10_000
"""Keys remembered at once; the oldest are forgotten beyond (an address flood is bounded)."""


class WindowLimit:
    """At most `count` events per `window_s` seconds per key."""

    def __init__(self, window_s: float = 60.0) -> None:
        self.window_s = window_s
        self._events: dict[str, deque[float]] = {}
        self._lock = threading.Lock()

    def allow(self, key: str, count: int) -> bool:
        """Record an event for `key` unless it has had `count` in the window."""
        now = time.monotonic()
        with self._lock:
            events = self._events.pop(key, None) or deque()
            while events and events[0] <= now - self.window_s:
                events.popleft()
            self._events[key] = events  # most recently used last
            if len(events) >= count:
                return False
            events.append(now)
            while len(self._events) > MAX_KEYS:
                del self._events[next(iter(self._events))]
            return True
