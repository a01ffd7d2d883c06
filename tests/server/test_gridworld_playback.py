"""The dashboard's playback of a grid world episode: the worker reruns it in the grid world
from its reset seed and logged actions, and shows the grid world's images."""

from __future__ import annotations

import io
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest
from PIL import Image

from tests.server.live import API_KEY, LiveServer
from tests.server.scale import rest_body, wait_for_status
from tests.server.test_episode_playback import API, HEADERS, _logged_steps, _ready

pytestmark = pytest.mark.slow


@pytest.fixture
def researcher(server: LiveServer) -> Iterator[httpx.Client]:
    """A logged-in dashboard (the login cookie), as the page's requests carry it."""
    with httpx.Client(base_url=server.url, timeout=60, headers=HEADERS) as client:
        assert client.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
        yield client


def test_a_grid_world_episode_is_rerun_and_played_back(
    server: LiveServer, researcher: httpx.Client
) -> None:
    body = rest_body(
        method="oracle", task="gridworld", seed=5, episodes=1, max_episode_steps=10,
        advice_budget=4, config={"pretraining_steps": 12, "batch_size": 8, "memory_size": 500},
    )  # fmt: skip
    with server.client() as api:
        study = api.post("/api/studies", json={"name": "grid world playback"}).json()
        made = api.post(f"/api/studies/{study['id']}/sessions", json=body)
        assert made.status_code == 201, made.text
        session: dict[str, Any] = made.json()
        assert api.post(f"/api/sessions/{session['id']}/start").status_code == 200
        wait_for_status(api, session["id"], {"finished"})
    listed = researcher.get(f"{API}/sessions/{session['id']}/episodes").json()
    assert ("pretrain", 1) in {(e["stage"], e["episode"]) for e in listed}
    assert all(e["playable"] for e in listed)

    for stage, number in (("pretrain", 1), ("train", 1)):
        opened = researcher.post(
            f"{API}/sessions/{session['id']}/episodes/{stage}/{number}/playback"
        )
        assert opened.status_code == 201, opened.text
        state = _ready(researcher, opened.json()["url"])
        assert state["state"] == "ready" and state["detail"] == "", state["detail"]
        shown = [(s["step"], s["action"], s["action_source"], s["reward"]) for s in state["steps"]]
        logged = _logged_steps(server, session["id"], stage, number)
        assert shown == [tuple(row) for row in logged] and len(shown) > 0
        assert {s["action"] for s in state["steps"]} <= set(range(4))
        image = researcher.get(state["steps"][0]["image_url"])
        assert image.headers["content-type"] == "image/png"
        pixels = np.asarray(Image.open(io.BytesIO(image.content)))
        assert pixels.shape == (64, 64, 3)  # the grid world's 8 squares of 8 pixels a side
        assert researcher.delete(opened.json()["url"]).status_code == 204
