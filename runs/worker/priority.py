"""Lowering a worker's CPU priority, so people's requests come before training.

Linux keeps the niceness (and the scheduling class) per thread, so `os.nice` in the main
thread leaves the threads that torch, PyBullet or the link already started at their old
priority; `lower_priority` changes every thread of the process, and threads started later
inherit it from the thread that starts them.
"""

from __future__ import annotations

import os
from pathlib import Path

TASKS = Path("/proc/self/task")


def lower_priority(nice: int, idle: bool = False) -> None:
    """Add `nice` to every thread's niceness; with `idle`, also put them in SCHED_IDLE
    (Linux: they run only when no ordinary task wants the CPU)."""
    if not TASKS.is_dir():  # not Linux: the process's niceness is all there is
        if nice:
            os.nice(nice)
        return
    for task in TASKS.iterdir():
        tid = int(task.name)
        try:
            if nice:
                current = os.getpriority(os.PRIO_PROCESS, tid)
                os.setpriority(os.PRIO_PROCESS, tid, min(19, current + nice))
            if idle:
                os.sched_setscheduler(tid, os.SCHED_IDLE, os.sched_param(0))
        except ProcessLookupError:
            continue  # the thread ended meanwhile
