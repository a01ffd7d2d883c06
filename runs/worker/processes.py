"""How a training worker process starts: forked from a fork server that has loaded torch,
PyBullet and the learner once, or spawned where the platform has no fork server.

Both the web process's session workers (`server.live.workers`) and a batch's workers
(`runs.batch.backends`) start this way. Starting a worker by spawning imports torch,
PyBullet, the learner and the batch's analysis again in every process (about 3 s of CPU
each); forked from the fork server, a worker starts in milliseconds and shares the loaded
pages copy-on-write. A worker sees the environment variables as they were when its
process's fork server started (at its first worker).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Sequence

WORKER_PRELOAD = ("torch", "pybullet", "learner.trainer", "sim.env", "runs.worker.worker")
"""What every session worker imports, loaded once in the fork server: `import torch` alone
leaves about 140 MB of private memory in a process; forked from a server that holds it,
the workers share those pages (copy on write) instead of each making its own."""


def worker_context(
    preload: Sequence[str] = WORKER_PRELOAD,
) -> multiprocessing.context.ForkServerContext | multiprocessing.context.SpawnContext:
    """Workers forked from a fork server that has loaded `preload` (a clean single-threaded
    process started for the purpose, never the caller with its threads), or spawned where
    the platform has no fork server. Each worker still owns its PyBullet client, torch
    threads and everything it makes after the fork. One fork server serves a process: the
    first of its workers to start decides what it has loaded (the rest import what it
    lacks)."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(preload))
    return context
