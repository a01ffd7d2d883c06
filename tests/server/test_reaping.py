"""A worker's process joined from several threads at once (its reader thread when the pipe
closes, a kill, the shutdown) reads the same exit code in each: `server.live.reaping`."""

from __future__ import annotations

import multiprocessing
import threading
import time
from collections.abc import Callable
from multiprocessing.process import BaseProcess

from server.live.reaping import join


def _plain(process: BaseProcess, timeout: float) -> int | None:
    process.join(timeout)
    return process.exitcode


def _wrong_codes(
    joiner: Callable[[BaseProcess, float], int | None], rounds: int, first: bool = False
) -> int:
    """Rounds in which one of three threads joining a short-lived child read no exit code
    (`first`: stop at the first such round)."""
    context = multiprocessing.get_context("fork")
    wrong = 0
    for _ in range(rounds):
        process = context.Process(target=time.sleep, args=(0.01,))
        process.start()
        codes: list[int | None] = []
        threads = [
            threading.Thread(target=lambda c=codes, p=process: c.append(joiner(p, 5)))
            for _ in range(3)
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        wrong += codes != [0, 0, 0]
        if first and wrong:
            break
    return wrong


def test_threads_joining_one_worker_all_read_its_exit_code() -> None:
    assert _wrong_codes(join, rounds=40) == 0


def test_without_it_the_threads_race() -> None:
    """What `join` prevents, seen: plain `Process.join` from three threads (if this ever
    stops failing, multiprocessing fixed the race and `reaping` can go)."""
    assert _wrong_codes(_plain, rounds=400, first=True) > 0
