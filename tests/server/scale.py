"""Reduced scales for the session tests: few episodes, little pretraining, small batches."""

from __future__ import annotations

import io
import time
import zipfile
from typing import Any

import httpx
import numpy as np
from PIL import Image

SMALL_CONFIG: dict[str, Any] = {"pretraining_steps": 60, "batch_size": 16, "memory_size": 2000}
EPISODES = 3
MAX_EPISODE_STEPS = 40
NONDETERMINISTIC = {
    *("time", "wall_time", "logged_at", "elapsed_s"),
    *("requested_at", "answered_at", "response_time_s"),
}


def session_body(method: str, **extra: Any) -> dict[str, Any]:
    return {
        "method": method,
        "seed": 11,
        "config": dict(SMALL_CONFIG),
        "episodes": EPISODES,
        "max_episode_steps": MAX_EPISODE_STEPS,
        "motion": "fast",
        **extra,
    }


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
    raise AssertionError(f"session {session_id} stayed {session['status']}")


def export(api: httpx.Client, study_id: int) -> dict[str, Any]:
    """The study's zip export, as {file name: bytes}."""
    response = api.get(f"/api/studies/{study_id}/export")
    assert response.status_code == 200, response.text
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def decode_png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)))
