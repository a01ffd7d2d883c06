"""One tqdm bar for a whole batch: runs done (running ones count by their episodes),
which are running and how far, and the time left; and, when the machine is shared (its
load average above its cores), what that costs the batch: the share of a core each worker
gets, measured from the workers' CPU time, and so how much slower its runs go than on a
quiet machine."""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, Protocol

from tqdm import tqdm

from runs.batch.spec import Run
from study.db.models import Status, StudySession

BAR_FORMAT = (
    "{desc} {percentage:3.0f}%|{bar}| {n:.1f}/{total} runs [{elapsed}<{remaining}{postfix}]"
)


SHARE_WINDOW_S = 10.0
"""The workers' share of their cores is measured over at least this long."""


def cpu_seconds(pid: int) -> float | None:
    """CPU time (user and system) of process `pid` on this machine (Linux's /proc), or None."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


class MachineShare:
    """Whether the machine is shared (load average above `cores`), and the share of the
    `threads` cores it needs that each of the batch's workers gets."""

    def __init__(self, cores: int, threads: int, window_s: float = SHARE_WINDOW_S) -> None:
        self.cores = cores
        self.threads = max(1, threads)
        self.window_s = window_s
        self._since: dict[int, tuple[float, float]] = {}
        self.share: float | None = None
        """The workers' mean share of the cores they need, over the last window."""

    def sample(self, pids: Iterable[int]) -> None:
        """Read the workers' CPU time; update `share` once a window has passed."""
        now = time.monotonic()
        shares = []
        for pid in set(pids):
            cpu = cpu_seconds(pid)
            if cpu is None:
                continue
            since = self._since.setdefault(pid, (now, cpu))
            if now - since[0] >= self.window_s:
                shares.append((cpu - since[1]) / (now - since[0]) / self.threads)
                self._since[pid] = (now, cpu)
        if shares:
            self.share = min(1.0, sum(shares) / len(shares))

    def line(self) -> str | None:
        """'machine shared: ...' while the load is above the cores, else None."""
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
        if load <= self.cores:
            return None
        text = f"machine shared: load {load:.1f} on {self.cores} cores"
        if self.share is not None and self.share > 0:
            text += (
                f", workers get {self.share:.0%} of the CPU they need: runs about "
                f"{1 / self.share:.1f}x slower than on a quiet machine"
            )
        return text


class RunState(Protocol):
    """What the bar reads of a run (`runs.batch.runner.RunState`, which uses the bar)."""

    run: Run
    session_id: int | None
    status: str


def run_fraction(progress: dict[str, Any]) -> float:
    """How much of a run is done, by its training episodes (pretraining counts as none)."""
    episodes = progress.get("episodes") or 0
    if not episodes:
        return 0.0
    return min(1.0, float(progress.get("episode") or 0) / episodes)


class BatchProgress:
    def __init__(
        self, states: Sequence[RunState], enabled: bool = True, share: MachineShare | None = None
    ) -> None:
        self.states = states
        self.share = share
        done = sum(s.status == Status.finished.value for s in states)
        # smoothing=0: the time left comes from the average pace since the start, which
        # suits runs of similar length better than the last few updates.
        self.bar = tqdm(
            total=len(states),
            initial=done,
            desc="batch",
            bar_format=BAR_FORMAT,
            smoothing=0,
            disable=not enabled,
            dynamic_ncols=True,
        )

    def update(self, rows: dict[int, StudySession]) -> None:
        done = 0.0
        running = []
        for state in self.states:
            if state.status == Status.finished.value:
                done += 1
            elif state.status == Status.running.value and state.session_id in rows:
                progress = rows[state.session_id].progress or {}
                done += run_fraction(progress)
                where = (
                    f"{progress.get('episode', 0)}/{progress.get('episodes', '?')}"
                    if progress.get("stage") == "train"
                    else "pretraining"
                )
                running.append(f"{state.run.name} {where}")
        failed = sum(s.status == Status.failed.value for s in self.states)
        finished = sum(s.status == Status.finished.value for s in self.states)
        postfix = f"{finished} done, {len(running)} running"
        if failed:
            postfix += f", {failed} failed"
        if running:
            postfix += ": " + ", ".join(running)
        shared = self._shared(rows)
        if shared:
            postfix = f"{shared}; {postfix}"
        self.bar.n = round(done, 2)
        self.bar.set_postfix_str(postfix, refresh=False)
        self.bar.refresh()

    def _shared(self, rows: dict[int, StudySession]) -> str | None:
        if self.share is None:
            return None
        running = {s.session_id for s in self.states if s.status == Status.running.value}
        self.share.sample(
            row.worker_pid for sid, row in rows.items() if sid in running and row.worker_pid
        )
        return self.share.line()

    def write(self, message: str) -> None:
        self.bar.write(message)

    def close(self) -> None:
        self.bar.close()
