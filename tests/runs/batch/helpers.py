"""Tiny batches through the real command line: a SQLite file (or the PostgreSQL database
`DATABASE_URL` points at), real worker processes, reduced scales."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import create_engine, func, select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from study.db.models import Episode, Study, StudySession

ROOT = Path(__file__).absolute().parents[3]
EPISODES = 2
ADVICE = 8
SCALE = [
    "--episodes", str(EPISODES),
    "--pretraining-steps", "20",
    "--advice-budget", str(ADVICE),
    "--max-episode-steps", "15",
    "--set", "batch_size=8",
    "--set", "memory_size=200",
    "--checkpoint-every", "1",
    "--no-progress",
    "--advisor-check", "record",
]  # fmt: skip
"""Reduced scale: 20 pretraining steps, 8 advice, 2 episodes of at most 15 steps; an advisor
trained at this scale cannot pass its check, so it is checked and recorded, not refused."""


@dataclass(frozen=True)
class Place:
    """Where a test's batches write: the data folder and the database."""

    data_dir: Path
    url: str

    @property
    def flags(self) -> list[str]:
        return ["--data-dir", str(self.data_dir), "--database-url", self.url]

    def engine(self) -> Engine:
        return create_engine(self.url.replace("postgresql://", "postgresql+psycopg://", 1))


def environment() -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("DATABASE_URL", None)
    return env


def in_process(place: Place, capsys: Any, *args: str) -> tuple[int, str]:
    """`ideeprl ARGS` in the test's process (its workers are processes all the same):
    exit code, and output and errors together."""
    from cli.main import main

    try:
        code = main([*args, *place.flags])
    except SystemExit as error:  # argparse refused an option
        code = int(error.code or 0)
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def ideeprl(place: Place, *args: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    """`ideeprl ARGS` in its own process, on this place's database."""
    return subprocess.run(
        [sys.executable, "-m", "cli", *args, *place.flags],
        cwd=ROOT,
        env=environment(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def start_ideeprl(place: Place, *args: str, log: Path) -> subprocess.Popen[bytes]:
    with log.open("wb") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "cli", *args, *place.flags],
            cwd=ROOT,
            env=environment(),
            stdout=out,
            stderr=subprocess.STDOUT,
        )


def sessions(engine: Engine, study_id: int) -> list[StudySession]:
    with Session(engine) as db:
        query = select(StudySession).where(StudySession.study_id == study_id)
        return list(db.scalars(query.order_by(StudySession.id)))


def study_id(engine: Engine, name: str) -> int:
    with engine.connect() as c:
        found = c.scalar(select(Study.id).where(Study.name == name))
    assert found is not None, f"no study named {name}"
    return int(found)


def training_totals(engine: Engine, session_ids: list[int]) -> dict[int, tuple[int, float]]:
    """Per session: (training episodes, their summed collected reward), from the rows."""
    with engine.connect() as c:
        rows = c.execute(
            select(Episode.session_id, func.count(), func.sum(Episode.collected_reward))
            .where(Episode.session_id.in_(session_ids), Episode.stage == "train")
            .group_by(Episode.session_id)
        )
        return {int(s): (int(n), float(total)) for s, n, total in rows}


def read_csv(path: Path) -> list[dict[str, Any]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def is_png(path: Path) -> bool:
    return (
        path.is_file()
        and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        and (path.stat().st_size > 5000)
    )
