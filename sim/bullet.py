"""PyBullet, imported without its build banner.

Importing pybullet writes "pybullet build time: ..." from C to the process's stderr, past
Python's streams. At a terminal that line breaks the progress bar a batch redraws, once per
worker process. The package imports pybullet from here (`from sim.bullet import pybullet`),
with file descriptors 1 and 2 sent to /dev/null for the import only.
"""

import contextlib
import os
import sys
import threading

_lock = threading.Lock()


def _quiet_import() -> object:
    with _lock:
        if "pybullet" in sys.modules:  # imported already (and its banner written then)
            return sys.modules["pybullet"]
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):  # closed or replaced streams
                stream.flush()
        saved = [os.dup(fd) for fd in (1, 2)]
        try:
            with open(os.devnull, "wb") as null:
                for fd in (1, 2):
                    os.dup2(null.fileno(), fd)
                import pybullet
        finally:
            for fd, copy in zip((1, 2), saved, strict=True):
                os.dup2(copy, fd)
                os.close(copy)
        return pybullet


_quiet_import()
import pybullet  # noqa: E402  (from sys.modules: the quiet import above made it)

__all__ = ["pybullet"]
