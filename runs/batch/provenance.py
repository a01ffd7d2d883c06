"""What a result needs beside its numbers: the software and machine it ran on, and how
long its runs took."""

from __future__ import annotations

import os
import platform
from collections.abc import Sequence
from importlib import metadata

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from runs.batch.backends import usable_cores
from study.db.models import Step

PAUSE_S = 60.0
"""A gap this long between two steps of a run is an interruption, not training time."""


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def environment() -> list[str]:
    """One line each: software versions, machine, and the device torch trains on."""
    import torch

    device = f"CUDA ({torch.cuda.get_device_name(0)})" if torch.cuda.is_available() else "CPU only"
    return [
        f"Python {platform.python_version()}, torch {torch.__version__}, pybullet "
        f"{_version('pybullet')}, gymnasium {_version('gymnasium')}, numpy {np.__version__}",
        f"{platform.platform()}; {cpu_model()}, {usable_cores()} usable cores "
        f"({os.cpu_count()} on the host); {device}",
    ]


def training_times(db: Session, session_ids: Sequence[int]) -> dict[int, float]:
    """Seconds each session spent running (first to last step, pauses longer than
    `PAUSE_S` left out, so a run done in pieces counts only its pieces)."""
    times = {}
    for session_id in session_ids:
        stamps = np.fromiter(
            db.scalars(
                select(Step.wall_time)
                .where(Step.session_id == session_id)
                .order_by(Step.global_step)
            ),
            dtype=float,
        )
        gaps = np.diff(stamps)
        times[session_id] = float(gaps[gaps < PAUSE_S].sum()) if len(gaps) else 0.0
    return times


def describe_times(times: dict[int, float]) -> str:
    values = np.array([t for t in times.values() if t > 0])
    if not len(values):
        return "no training time recorded"
    return (
        f"{len(values)} runs, each {np.median(values) / 60:.1f} min median "
        f"({values.min() / 60:.1f}-{values.max() / 60:.1f}), "
        f"{values.sum() / 3600:.2f} h in all"
    )
