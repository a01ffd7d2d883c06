"""The batch's progress line says when the machine is shared, and what it costs."""

from __future__ import annotations

import os
import time

from runs.batch.progress import MachineShare, cpu_seconds


def busy(seconds: float) -> None:
    """Compute for at least `seconds` of CPU time (not wall time: the machine may be shared)."""
    start = time.process_time()
    while time.process_time() - start < seconds:
        sum(range(1000))


def test_a_shared_machine_is_named_with_the_share_its_workers_get() -> None:
    share = MachineShare(cores=0, threads=1, window_s=0.05)  # any load is above 0 cores
    share.sample([os.getpid()])
    busy(0.1)
    share.sample([os.getpid()])
    assert share.share is not None and 0 < share.share <= 1
    line = share.line()
    assert line is not None and line.startswith("machine shared: load ")
    assert "on 0 cores, workers get " in line and "x slower than on a quiet machine" in line


def test_a_quiet_machine_says_nothing() -> None:
    share = MachineShare(cores=10**6, threads=1)
    share.sample([os.getpid()])
    assert share.share is None  # no window has passed yet
    assert share.line() is None


def test_cpu_time_of_a_process_that_is_gone_is_unknown() -> None:
    assert cpu_seconds(os.getpid()) is not None
    assert cpu_seconds(2**22 + 12345) is None
