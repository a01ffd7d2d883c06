"""One tqdm bar for a whole batch: runs done (running ones count by their episodes),
which are running and how far, and the time left."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from tqdm import tqdm

from server.batch.spec import Run
from server.db.models import Status, StudySession

BAR_FORMAT = (
    "{desc} {percentage:3.0f}%|{bar}| {n:.1f}/{total} runs [{elapsed}<{remaining}{postfix}]"
)


class RunState(Protocol):
    """What the bar reads of a run (`server.batch.runner.RunState`, which uses the bar)."""

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
    def __init__(self, states: Sequence[RunState], enabled: bool = True) -> None:
        self.states = states
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
        self.bar.n = round(done, 2)
        self.bar.set_postfix_str(postfix, refresh=False)
        self.bar.refresh()

    def write(self, message: str) -> None:
        self.bar.write(message)

    def close(self) -> None:
        self.bar.close()
