"""Waiting for a child process from more than one thread.

Two threads in `Process.join` at once race in `os.waitpid`: the one that reaps the child
sets its exit code only once it has the GIL back, and the other gets `ECHILD`, after which
`multiprocessing` reads the child as still alive with no exit code. A worker's reader
thread joins its process when the pipe closes while a kill may join it too, so every join
of a worker goes through `join`: one thread at a time per process."""

from __future__ import annotations

import threading
import weakref
from multiprocessing.process import BaseProcess

_locks: weakref.WeakKeyDictionary[BaseProcess, threading.Lock] = weakref.WeakKeyDictionary()
_guard = threading.Lock()


def join(process: BaseProcess, timeout: float | None = None) -> int | None:
    """Wait at most `timeout` seconds for `process` to end; its exit code (None: still
    running)."""
    with _guard:
        lock = _locks.setdefault(process, threading.Lock())
    with lock:
        process.join(timeout)
        return process.exitcode
