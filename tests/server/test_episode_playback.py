"""The dashboard's playback of a recorded episode, over its JSON: a worker process reruns
the episode from its reset seed and logged actions and gives back what the learner saw;
everything a researcher can get wrong gets a 4xx that says what to do."""

from __future__ import annotations

import io
import time
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest
from PIL import Image
from sqlalchemy import create_engine, select, update

from learner.run import RunSpec
from runs.worker.rerun import RerunOrder
from server.live.playbacks import Playbacks, TooManyPlaybacks
from study.db.models import Episode, Step
from tests.server.live import API_KEY, LiveServer
from tests.server.scale import rest_body, wait_for_status

HEADERS = {"X-Requested-With": "test"}
API = "/dashboard/api"


@pytest.fixture(scope="module")
def recorded(server: LiveServer) -> dict[str, Any]:
    """A finished tiny oracle session: a few pretraining episodes' steps, one training
    episode."""
    body = rest_body(
        method="oracle",
        seed=5,
        config={"pretraining_steps": 12, "batch_size": 8, "memory_size": 500},
        episodes=1,
        max_episode_steps=10,
        advice_budget=4,
        motion="fast",
    )
    with server.client() as api:
        study = api.post("/api/studies", json={"name": "playback"}).json()
        session = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
        assert api.post(f"/api/sessions/{session['id']}/start").status_code == 200
        wait_for_status(api, session["id"], {"finished"})
    return session


@pytest.fixture
def dashboard(server: LiveServer) -> Iterator[httpx.Client]:
    """A logged-in dashboard (the login cookie), as the page's requests carry it."""
    with httpx.Client(base_url=server.url, timeout=60, headers=HEADERS) as client:
        assert client.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
        yield client


def _logged_steps(server: LiveServer, session_id: int, stage: str, number: int) -> list[Any]:
    engine = create_engine(server.database_url)
    try:
        with engine.connect() as db:
            episode = db.execute(
                select(Episode).where(
                    Episode.session_id == session_id,
                    Episode.stage == stage,
                    Episode.episode == number,
                )
            ).one()
            return list(
                db.execute(
                    select(Step.episode_step, Step.action, Step.action_source, Step.reward)
                    .where(
                        Step.session_id == session_id,
                        Step.global_step.between(
                            episode.first_global_step, episode.last_global_step
                        ),
                    )
                    .order_by(Step.global_step)
                )
            )
    finally:
        engine.dispose()


def _ready(client: httpx.Client, url: str) -> dict[str, Any]:
    deadline = time.monotonic() + 120
    while True:
        state = client.get(url).json()
        if state["state"] != "rerunning":
            return state
        assert time.monotonic() < deadline, "the rerun never ended"
        time.sleep(0.2)


def test_a_playback_reruns_the_logged_episode(
    server: LiveServer, recorded: dict[str, Any], dashboard: httpx.Client
) -> None:
    session_id = recorded["id"]
    listed = dashboard.get(f"{API}/sessions/{session_id}/episodes").json()
    assert {("train", 1), ("pretrain", 1)} <= {(e["stage"], e["episode"]) for e in listed}
    assert all(e["playable"] for e in listed)

    opened = dashboard.post(f"{API}/sessions/{session_id}/episodes/pretrain/1/playback")
    assert opened.status_code == 201, opened.text
    state = _ready(dashboard, opened.json()["url"])
    assert state["state"] == "ready" and state["detail"] == "", state["detail"]
    shown = [(s["step"], s["action"], s["action_source"], s["reward"]) for s in state["steps"]]
    assert shown == [tuple(row) for row in _logged_steps(server, session_id, "pretrain", 1)]
    # The oracle's advice at the end of pretraining: shown at its step, with its image.
    assert state["advice"], "early advising advises the last pretraining steps"
    for advice in state["advice"]:
        step = state["steps"][advice["index"]]
        assert step["global_step"] == advice["global_step"]
        assert step["action_source"] == "advisor" and step["action"] == advice["action"]
        seen = dashboard.get(step["image_url"])
        stored = dashboard.get(advice["image_url"])
        assert seen.headers["content-type"] == stored.headers["content-type"] == "image/png"
        pixels = np.asarray(Image.open(io.BytesIO(seen.content)))
        assert pixels.shape == (64, 64, 3)
        assert np.array_equal(pixels, np.asarray(Image.open(io.BytesIO(stored.content))))

    url = opened.json()["url"]
    assert dashboard.post(f"{url}/show", json={"index": 1}).json() == {"views": 0}
    assert dashboard.delete(url).status_code == 204
    assert dashboard.get(url).status_code == 404
    assert dashboard.delete(url).status_code == 404


def test_what_cannot_be_played_back_is_refused(
    server: LiveServer, recorded: dict[str, Any], dashboard: httpx.Client
) -> None:
    session_id = recorded["id"]
    start = f"{API}/sessions/{session_id}/episodes"
    with httpx.Client(base_url=server.url, timeout=30, headers=HEADERS) as stranger:
        assert stranger.post(f"{start}/train/1/playback").status_code == 401
        assert stranger.get(f"{start}").status_code == 401
        assert stranger.get(f"/dashboard/sessions/{session_id}/playback").status_code == 303
    no_header = dashboard.post(f"{start}/train/1/playback", headers={"X-Requested-With": ""})
    assert no_header.status_code == 403
    for path, status in (
        (f"{API}/sessions/999999/episodes/train/1/playback", 404),
        (f"{start}/train/99/playback", 404),
        (f"{start}/warmup/1/playback", 422),
        (f"{start}/train/0/playback", 422),
        (f"{start}/train/99999999999/playback", 422),
    ):
        response = dashboard.post(path)
        assert response.status_code == status, (path, response.text)
        assert response.json()["detail"]
    assert dashboard.get(f"{API}/playbacks/nosuchplayback").status_code == 404
    assert dashboard.get(f"{API}/playbacks/no%20such").status_code == 422
    assert dashboard.get(f"{API}/sessions/{session_id}/advice/9999.png").status_code == 404

    opened = [dashboard.post(f"{start}/train/1/playback") for _ in range(2)]
    assert [o.status_code for o in opened] == [201, 201]
    try:
        third = dashboard.post(f"{start}/pretrain/1/playback")
        assert third.status_code == 429 and "playbacks are open" in third.json()["detail"]
        url = opened[0].json()["url"]
        steps = len(_ready(dashboard, url)["steps"])
        assert dashboard.post(f"{url}/show", json={"index": steps}).status_code == 200  # end
        assert dashboard.post(f"{url}/show", json={"index": steps + 1}).status_code == 422
        assert dashboard.post(f"{url}/show", json={"index": -1}).status_code == 422
        assert dashboard.post(f"{url}/show", json={"step": 1}).status_code == 422
        assert dashboard.get(f"{url}/steps/{steps}.png").status_code == 200  # the end's image
        assert dashboard.get(f"{url}/steps/{steps + 1}.png").status_code == 404
    finally:
        for o in opened:
            assert dashboard.delete(o.json()["url"]).status_code == 204
    again = dashboard.post(f"{start}/pretrain/1/playback")
    assert again.status_code == 201, "a closed playback frees its place"
    assert dashboard.delete(again.json()["url"]).status_code == 204

    engine = create_engine(server.database_url)
    try:
        with engine.begin() as db:
            db.execute(
                update(Episode)
                .where(Episode.session_id == session_id, Episode.stage == "train")
                .values(reset_seed=None)
            )
    finally:
        engine.dispose()
    unseeded = dashboard.post(f"{start}/train/1/playback")
    assert unseeded.status_code == 409 and "reset seed" in unseeded.json()["detail"]
    listed = dashboard.get(start).json()
    assert [e["playable"] for e in listed if e["stage"] == "train"] == [False]


def test_deleting_the_session_ends_its_playbacks(
    server: LiveServer, recorded: dict[str, Any], dashboard: httpx.Client
) -> None:
    """What a playback holds of a participant goes with their data (runs last: it deletes
    the module's session)."""
    opened = dashboard.post(f"{API}/sessions/{recorded['id']}/episodes/pretrain/1/playback")
    assert opened.status_code == 201
    url = opened.json()["url"]
    assert dashboard.get(url).status_code == 200
    with server.client() as api:
        assert api.delete(f"/api/sessions/{recorded['id']}").status_code == 204
    assert dashboard.get(url).status_code == 404


def test_an_idle_playback_is_closed_and_its_rerun_ended() -> None:
    """Without a request from its page for `idle_s`, a playback goes, and frees its place."""
    now = [0.0]
    closed: list[str] = []
    playbacks = Playbacks(
        1, idle_s=60, on_close=lambda p: closed.append(p.id), clock=lambda: now[0]
    )
    # A long episode, so the rerun is still going when the playback is swept.
    order = RerunOrder(
        spec=RunSpec(method="autonomous", motion="physics"),
        reset_seed=1,
        actions=[1, 2] * 100,
        rewards=[0.0] * 200,
    )
    first = playbacks.start(1, "train", 1, order)
    with pytest.raises(TooManyPlaybacks):
        playbacks.start(1, "train", 1, order)
    now[0] = 30.0
    assert playbacks.get(first.id) is first  # a request: idle from now
    now[0] = 85.0
    assert playbacks.sweep() == []
    now[0] = 91.0
    assert playbacks.sweep() == [first.id] and closed == [first.id]
    assert first.process is not None and not first.process.is_alive()
    assert playbacks.get(first.id) is None
    second = playbacks.start(1, "train", 1, order)
    playbacks.close_all()
    assert second.process is not None and not second.process.is_alive()
