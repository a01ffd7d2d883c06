"""A profiler hook that writes, per process, every entry into a function of the project's
source files (tests/test_walks.py says exactly what is counted).

One line per event, tab-separated: monotonic ns; the event (`call CALLER`, CALLER as
`_caller` says; `answer N`: `WorkerLink._recv` returned the `AdviceAnswer` for advice N);
the thread's name; the asyncio task (on the main thread: the task's id; on another thread:
the id of the task whose context its thread-pool call copied, else 0: a request and the
thread-pool calls it makes share one); the file, relative to the root; the function.
Not counted: module and class bodies and all they call (import time), a suspended generator
or coroutine resuming (it was entered when it began), frames outside the project's
packages (third-party code is transparent), tests.
"""

from __future__ import annotations

import asyncio
import contextvars
import os
import sys
import threading
import time
from typing import Any

PACKAGES = ("sim", "learner", "study", "runs", "server", "analysis", "cli")
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CO_NEWLOCALS = 0x2  # a function's code (not a module's or a class body's)
CO_GENERATOR_LIKE = 0x20 | 0x80 | 0x200  # generator, coroutine, async generator

_walk: contextvars.ContextVar[int] = contextvars.ContextVar("walk")
_files: dict[str, str | None] = {}


def project_file(filename: str) -> str | None:
    """`server/routes/sessions.py` for a project source file, else None (cached)."""
    known = _files.get(filename, "")
    if known != "":
        return known
    found = None
    path = os.path.abspath(filename)
    if path.startswith(ROOT + os.sep) and path.endswith(".py"):
        relative = os.path.relpath(path, ROOT)
        if relative.split(os.sep)[0] in PACKAGES:
            found = relative.replace(os.sep, "/")
    _files[filename] = found
    return found


class _Out:
    """This process's trace file, line-buffered (a worker may be killed, or leave by
    os._exit); a forked child, such as a forkserver's worker, opens its own."""

    def __init__(self, folder: str) -> None:
        self.folder = folder
        self.open()
        os.register_at_fork(after_in_child=self.open)

    def open(self) -> None:
        self.lock = threading.Lock()
        name = os.path.join(self.folder, f"trace-{os.getpid()}.tsv")
        self.file = open(name, "a", buffering=1)  # noqa: SIM115

    def write(self, line: str) -> None:
        with self.lock:
            self.file.write(line)


def _caller(frame: Any, name: str) -> str:
    """`FILE` of the innermost project frame that called this one (`-`: none); `FILE!`
    when the call climbs back: the callee's file is further up the stack, under another
    file's frame (A -> B -> A)."""
    caller = None
    back = frame.f_back
    while back is not None:
        found = project_file(back.f_code.co_filename)
        if found is not None:
            if caller is None:
                caller = found
                if found == name:
                    return caller
            elif found == name:
                return caller + "!"
        back = back.f_back
    return caller or "-"


def install(folder: str) -> None:
    os.makedirs(folder, exist_ok=True)
    out = _Out(folder)

    importing = threading.local()
    main = threading.main_thread()

    def hook(frame: Any, event: str, arg: Any) -> None:
        code = frame.f_code
        if code.co_name == "<module>" and frame.f_globals.get("__name__") != "__main__":
            # import time: nothing it runs is counted (a program's own __main__ is not an
            # import: `python -m cli`, `python -c ...spawn_main(...)`)
            if event == "call":
                importing.depth = getattr(importing, "depth", 0) + 1
            elif event == "return":  # (the hook starts inside sitecustomize's import)
                importing.depth = max(0, getattr(importing, "depth", 0) - 1)
            return
        if getattr(importing, "depth", 0):
            return
        if event == "call":
            if not code.co_flags & CO_NEWLOCALS:
                return  # a class body
            name = project_file(code.co_filename)
            if name is None:
                return
            if code.co_flags & CO_GENERATOR_LIKE and code.co_code[frame.f_lasti + 1]:
                return  # resumed (at a RESUME whose argument is not 0), not entered
            kind = "call " + _caller(frame, name)
        elif event == "return" and arg is not None and type(arg).__name__ == "AdviceAnswer":
            if code.co_name != "_recv":
                return
            name = project_file(code.co_filename)
            if name is None:
                return
            kind = f"answer {arg.advice_index}"
        else:
            return
        walk = _walk.get(0)
        if threading.current_thread() is main:  # the asyncio task is the request
            loop = asyncio._get_running_loop()
            task = asyncio.current_task(loop) if loop is not None else None
            if task is not None and walk != id(task):
                walk = id(task)
                _walk.set(walk)  # a thread-pool call the task makes copies its context
        line = (
            f"{time.monotonic_ns()}\t{kind}\t{threading.current_thread().name}\t{walk}\t"
            f"{name}\t{code.co_qualname}\n"
        )
        out.write(line)

    threading.setprofile(hook)
    sys.setprofile(hook)
