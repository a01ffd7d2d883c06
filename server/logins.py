"""Dashboard logins held by the server: a random value in the cookie, its hash and expiry
here. Logging out forgets it at once; so does the end of its time, and a restart (the
researcher logs in again). One web process serves the dashboard, so memory is the store."""

from __future__ import annotations

import hashlib
import secrets
import threading
import time


def _digest(value: str) -> str:
    return hashlib.sha256(value.encode("utf-8", "backslashreplace")).hexdigest()


class Logins:
    def __init__(self, lifetime_s: float) -> None:
        self.lifetime_s = lifetime_s
        self._expiry: dict[str, float] = {}
        self._lock = threading.Lock()

    def issue(self) -> str:
        """A new login; the cookie holds what this returns, the server only its hash."""
        value = secrets.token_urlsafe(32)
        now = time.monotonic()
        with self._lock:
            self._expiry = {k: t for k, t in self._expiry.items() if t > now}
            self._expiry[_digest(value)] = now + self.lifetime_s
        return value

    def valid(self, value: str) -> bool:
        if not value or len(value) > 200:
            return False
        with self._lock:
            expiry = self._expiry.get(_digest(value))
        return expiry is not None and expiry > time.monotonic()

    def revoke(self, value: str) -> None:
        with self._lock:
            self._expiry.pop(_digest(value), None)
