"""A worker's lowered priority reaches every thread it has (Linux keeps niceness and the
scheduling class per thread: `os.nice` alone leaves torch's threads where they were)."""

from __future__ import annotations

import multiprocessing
import os
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="per-thread priorities: Linux")


def _threads() -> dict[int, tuple[int, int]]:
    """Each thread's (niceness, scheduling policy)."""
    out = {}
    for task in Path("/proc/self/task").iterdir():
        fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        out[int(task.name)] = (int(fields[16]), int(fields[38]))
    return out


def _lowered(idle: bool, queue: multiprocessing.Queue) -> None:
    import torch

    from runs.worker.priority import lower_priority

    torch.set_num_threads(2)
    x = torch.randn(256, 256)
    (x @ x).sum()  # torch's own threads exist now
    before = _threads()
    lower_priority(5, idle=idle)
    queue.put((before, _threads()))


@pytest.mark.parametrize("idle", [False, True])
def test_every_thread_is_lowered(idle: bool) -> None:
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    process = context.Process(target=_lowered, args=(idle, queue))
    process.start()
    before, after = queue.get(timeout=120)
    process.join(60)
    assert len(before) > 1, "torch started threads of its own"
    base = os.getpriority(os.PRIO_PROCESS, 0)
    policy = os.SCHED_IDLE if idle else os.SCHED_OTHER
    assert all(nice == base for nice, _ in before.values())
    assert after.keys() == before.keys()
    assert all(nice == min(19, base + 5) and p == policy for nice, p in after.values()), after
