"""Records on disk: CSV files as a run goes, and the learning-curve figure.

The server stores records in its database through its own callback; these serve the
command line and anyone who runs the trainer from a script.
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np
from matplotlib.figure import Figure

from learner.records import STORED_Q, EpisodeRecord, StepRecord, named_q

EPISODE_COLUMNS = [f.name for f in dataclasses.fields(EpisodeRecord)]
SORTING_ACTIONS = ("grab", "move_right", "move_left", "drop")
"""The sorting robot's action names (`tasks.Task.action_names`), the default task's."""


def step_columns(actions: Sequence[str]) -> list[str]:
    """steps.csv's columns: the `StepRecord`'s, its Q-values one `q_<name>` column per
    action of the run's task (`actions`, its action names in order)."""
    columns = []
    for field in dataclasses.fields(StepRecord):
        if field.name == STORED_Q[0]:
            columns += [f"q_{name}" for name in actions]
        elif field.name not in STORED_Q:
            columns.append(field.name)
    return columns


class CsvRecorder:
    """A trainer callback appending to `steps.csv` and `episodes.csv` in `out_dir`,
    flushed at every episode's end; a step's Q-values under its task's action names
    (`actions`). With `resume_from_step`, rows after that global step (written after the
    checkpoint a run resumes from) are dropped first, so the files read as one
    uninterrupted run (rows that held the Q-values by position, `StepRecord`'s own fields,
    are given the names)."""

    def __init__(
        self,
        out_dir: str | Path,
        resume_from_step: int | None = None,
        actions: Sequence[str] = SORTING_ACTIONS,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.actions = tuple(actions)
        step_fields = step_columns(self.actions)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.steps_path = self.out_dir / "steps.csv"
        self.episodes_path = self.out_dir / "episodes.csv"
        if resume_from_step is None:
            for path in (self.steps_path, self.episodes_path):
                path.unlink(missing_ok=True)
        else:
            _keep_rows(self.steps_path, "global_step", resume_from_step, step_fields, self._named)
            _keep_rows(self.episodes_path, "last_global_step", resume_from_step)
        self._steps, self._step_writer = _open(self.steps_path, step_fields)
        self._episodes, self._episode_writer = _open(self.episodes_path, EPISODE_COLUMNS)

    def _named(self, step: Mapping[str, Any]) -> dict[str, Any]:
        """A step (a record's fields, or a row) with its Q-values under the task's names
        (the fields they are stored in by position are left for the writer to drop)."""
        named = all(f"q_{name}" in step for name in self.actions)
        if named and step.get("q_values") in (None, ""):
            return dict(step)
        return dict(step) | named_q(step, self.actions)

    def on_step(self, record: StepRecord) -> None:
        self._step_writer.writerow(self._named(record.to_dict()))

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
    writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
    if new:
        writer.writeheader()
    return handle, writer


def _keep_rows(
    path: Path,
    column: str,
    last_step: int,
    columns: Sequence[str] | None = None,
    named: Callable[[Mapping[str, Any]], dict[str, Any]] | None = None,
) -> None:
    """Keep the rows up to `last_step`, under `columns` where given (the file's own
    otherwise); `named` gives a step row its Q-value columns first."""
    if not path.exists():
        return
    with path.open(newline="") as handle:
        reader = csv.DictReader(handle)
        fields = list(columns or reader.fieldnames or [])
        rows = [row for row in reader if int(row[column]) <= last_step]
    if named is not None:
        rows = [named(row) for row in rows]
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields, extrasaction="ignore")
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
