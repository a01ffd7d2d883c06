"""Reduced scales for the session tests: few episodes, little pretraining, small batches."""

from __future__ import annotations

import io
import time
import zipfile
from typing import Any

import httpx
import numpy as np
from PIL import Image
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from learner.fields import leaves, nest
from learner.run import RunSpec
from study.db.models import Episode, Step
from study.schemas.sessions import NOT_THE_RUN

SMALL_CONFIG: dict[str, Any] = {"pretraining_steps": 60, "batch_size": 16, "memory_size": 2000}
EPISODES = 3
MAX_EPISODE_STEPS = 40
NONDETERMINISTIC = {
    *("time", "wall_time", "logged_at", "elapsed_s"),
    *("requested_at", "answered_at", "response_time_s"),
}

LEFT_OUT = {"id", "session_id", *NONDETERMINISTIC}


def records(factory: sessionmaker[Session], session_id: int) -> list[tuple[Any, ...]]:
    """The session's steps and episodes, less what differs between two runs of one seed."""
    rows: list[tuple[Any, ...]] = []
    with factory() as db:
        for table, order in ((Step, Step.global_step), (Episode, Episode.last_global_step)):
            columns = [c for c in table.__table__.columns if c.name not in LEFT_OUT]
            query = select(*columns).where(table.session_id == session_id).order_by(order)
            rows += [tuple(row) for row in db.execute(query)]
    return rows


GROUPS = tuple({leaf.path[0] for leaf in leaves(RunSpec) if len(leaf.path) > 1})
"""The run's nested groups (`config`, `strategy_options`, `scenario`)."""


def rest_body(**fields: Any) -> dict[str, Any]:
    """A session's REST body from the run's fields by their names (a group's as a dict, e.g.
    `scenario={...}`, `config={...}`) and the session's own options (`label`, `participant`,
    `idle_limit_s`, `keep_replay_memory`), which go beside `run`."""
    own = {name: fields.pop(name) for name in list(fields) if name in NOT_THE_RUN}
    groups = {name: fields.pop(name) for name in GROUPS if isinstance(fields.get(name), dict)}
    run = nest(fields, RunSpec)
    for name, given in groups.items():
        run[name] = {**run.get(name, {}), **given}
    return {"run": run, **own}


def session_body(method: str, **extra: Any) -> dict[str, Any]:
    """A session's REST body at the tests' scale (`rest_body`'s names)."""
    scale = {
        "seed": 11,
        "episodes": EPISODES,
        "max_episode_steps": MAX_EPISODE_STEPS,
        "motion": "fast",
        **SMALL_CONFIG,
    }
    return rest_body(method=method, **{**scale, **extra})


def wait_for_status(
    api: httpx.Client, session_id: int, statuses: set[str], timeout: float = 180
) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        session = api.get(f"/api/sessions/{session_id}").json()
        if session["status"] in statuses:
            return session
        if session["status"] == "failed":
            raise AssertionError(f"session failed:\n{session['status_detail']}")
        time.sleep(0.2)
    raise AssertionError(
        f"session {session_id} stayed {session['status']}: {session.get('status_detail')}"
    )


def export(api: httpx.Client, study_id: int) -> dict[str, Any]:
    """The study's zip export, as {file name: bytes}."""
    response = api.get(f"/api/studies/{study_id}/export")
    assert response.status_code == 200, response.text
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def decode_png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)))
