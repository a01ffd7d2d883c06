"""Records on disk: CSV files as a run goes, and the learning-curve figure.

The server stores records in its database through its own callback; these serve the
command line and anyone who runs the trainer from a script.
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import IO

import numpy as np
from matplotlib.figure import Figure

from learner.records import EpisodeRecord, StepRecord

STEP_COLUMNS = [f.name for f in dataclasses.fields(StepRecord)]
EPISODE_COLUMNS = [f.name for f in dataclasses.fields(EpisodeRecord)]


class CsvRecorder:
    """A trainer callback appending to `steps.csv` and `episodes.csv` in `out_dir`,
    flushed at every episode's end. With `resume_from_step`, rows after that global step
    (written after the checkpoint a run resumes from) are dropped first, so the files
    read as one uninterrupted run."""

    def __init__(self, out_dir: str | Path, resume_from_step: int | None = None) -> None:
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.steps_path = self.out_dir / "steps.csv"
        self.episodes_path = self.out_dir / "episodes.csv"
        if resume_from_step is None:
            for path in (self.steps_path, self.episodes_path):
                path.unlink(missing_ok=True)
        else:
            _keep_rows(self.steps_path, "global_step", resume_from_step)
            _keep_rows(self.episodes_path, "last_global_step", resume_from_step)
        self._steps, self._step_writer = _open(self.steps_path, STEP_COLUMNS)
        self._episodes, self._episode_writer = _open(self.episodes_path, EPISODE_COLUMNS)

    def on_step(self, record: StepRecord) -> None:
        self._step_writer.writerow(record.to_dict())

    def on_episode(self, record: EpisodeRecord) -> None:
        self._episode_writer.writerow(record.to_dict())
        self.flush()

    def flush(self) -> None:
        self._steps.flush()
        self._episodes.flush()

    def close(self) -> None:
        self._steps.close()
        self._episodes.close()


def _open(path: Path, columns: list[str]) -> tuple[IO[str], csv.DictWriter[str]]:
    new = not path.exists() or path.stat().st_size == 0
    handle = path.open("a", newline="")
    writer = csv.DictWriter(handle, fieldnames=columns)
    if new:
        writer.writeheader()
    return handle, writer


def _keep_rows(path: Path, column: str, last_step: int) -> None:
    if not path.exists():
        return
    with path.open(newline="") as handle:
        reader = csv.DictReader(handle)
        fields = reader.fieldnames or []
        rows = [row for row in reader if int(row[column]) <= last_step]
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)


@dataclasses.dataclass(frozen=True)
class TrainingCurve:
    """The training episodes of an episodes.csv, in order: what the learning curve plots."""

    rewards: list[float]
    """Each training episode's collected reward."""
    epsilons: list[float]
    """The exploration rate each began with."""


def training_curve(path: str | Path) -> TrainingCurve:
    """The training episodes (stage `train`) of an episodes.csv, numbers parsed."""
    with Path(path).open(newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if row["stage"] == "train"]
    return TrainingCurve(
        [float(row["collected_reward"]) for row in rows], [float(row["epsilon"]) for row in rows]
    )


def learning_curve_figure(
    curves: dict[str, Sequence[float]],
    epsilon: Sequence[float] | None = None,
    title: str = "Collected reward per training episode",
    window: int = 10,
) -> Figure:
    """Collected reward per episode for one or more runs (thin), with a moving average
    (thick), and epsilon on a second axis when given. Built without pyplot, so it is safe
    in a server thread."""
    figure = Figure(figsize=(8, 4.5), layout="constrained")
    axes = figure.add_subplot()
    for index, (label, rewards) in enumerate(curves.items()):
        color = f"C{index}"
        episodes = np.arange(1, len(rewards) + 1)
        axes.plot(episodes, rewards, color=color, alpha=0.3, linewidth=0.8)
        if len(rewards) >= window:
            smooth = np.convolve(rewards, np.ones(window) / window, mode="valid")
            axes.plot(episodes[window - 1 :], smooth, color=color, linewidth=2, label=label)
        else:
            axes.plot(episodes, rewards, color=color, linewidth=2, label=label)
    axes.set_xlabel("training episode")
    axes.set_ylabel(f"collected reward ({window}-episode mean in bold)")
    axes.axhline(3.0, color="grey", linestyle=":", linewidth=1)
    axes.set_title(title)
    axes.legend(loc="lower right")
    if epsilon is not None and len(epsilon):
        twin = axes.twinx()
        twin.plot(
            np.arange(1, len(epsilon) + 1), epsilon, color="black", linestyle="--", linewidth=1
        )
        twin.set_ylabel("epsilon (dashed)")
        twin.set_ylim(0, 1.05)
    return figure


def plot_learning_curve(
    rewards: Sequence[float], epsilon: Sequence[float], path: str | Path, label: str
) -> Path:
    """Save a run's learning curve (training episodes) as a PNG."""
    path = Path(path)
    learning_curve_figure({label: rewards}, epsilon).savefig(path, dpi=120)
    return path
