"""The capacity benchmark's CPU accounting: processes that end before the run does are
counted (Chromium's were missed when counted at the end), each in its part."""

from __future__ import annotations

import subprocess
import sys

import pytest

from benchmarks.bench_capacity import CpuMeter

BURN = "import time\nend = time.process_time() + {s}\nwhile time.process_time() < end: pass\n"
TRAINER = (
    "import os, subprocess, sys, time\n"
    "os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))\n"
    "sys.stdin.readline()\n"
    f"subprocess.run([sys.executable, '-c', {BURN.format(s=0.6)!r}])\n"
    "print('trained', flush=True)\n"
    "time.sleep(120)\n"
)


@pytest.mark.slow
def test_processes_that_end_before_the_run_are_counted_in_their_part() -> None:
    # A stand-in server whose child trains (SCHED_IDLE) and ends; the server lives on.
    server = subprocess.Popen(
        [sys.executable, "-c", TRAINER], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert server.stdin is not None and server.stdout is not None
    try:
        meter = CpuMeter(server.pid, every_s=0.05).start()
        server.stdin.write("go\n")
        server.stdin.flush()  # its child starts training once the meter runs
        client = subprocess.Popen([sys.executable, "-c", BURN.format(s=0.6)])
        client.wait()  # reaped before the meter stops: only its samples count it
        assert server.stdout.readline() == "trained\n"  # the server's child burnt 0.6 s, ended
        parts = meter.stop()
    finally:
        server.kill()
        server.wait()
    assert 0.4 <= parts["protocol clients"] <= 1.5, parts  # the client (and this process)
    assert 0.4 <= parts["training"] <= 1.0, parts  # the server's SCHED_IDLE child
    assert parts["web process"] < 0.3, parts  # the server itself slept
    assert parts["browsers"] == 0.0, parts
