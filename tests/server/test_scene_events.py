"""The viewer's feed: scene and progress events flow from a worker to the web process's
hub, as issue 5's viser view will subscribe to them."""

from __future__ import annotations

import asyncio
import queue
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import uvicorn
from fastapi import FastAPI

from server.live.hub import HubEvent
from server.main import create_app
from study.settings import Settings
from tests.server.live import API_KEY, free_port, fresh_database
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body

pytestmark = pytest.mark.slow


@pytest.fixture
def app(tmp_path: Path) -> Iterator[tuple[FastAPI, str]]:
    """The app served by uvicorn on loopback, in this process, so the test can reach its hub."""
    with fresh_database(tmp_path) as url:
        port = free_port()
        settings = Settings(database_url=url, api_key=API_KEY, data_dir=tmp_path, port=port)
        app = create_app(settings)
        server = uvicorn.Server(uvicorn.Config(app, port=port, log_level="warning"))
        thread = threading.Thread(target=server.run, daemon=True)
        thread.start()
        while not server.started:
            time.sleep(0.05)
        try:
            yield app, f"http://127.0.0.1:{port}"
        finally:
            server.should_exit = True
            thread.join(60)


class Events:
    """Everything a subscriber received, searchable in order of arrival."""

    def __init__(self) -> None:
        self.arrived: queue.Queue[HubEvent] = queue.Queue()
        self.seen: list[HubEvent] = []

    def first(
        self, kind: str, where: Callable[[Any], bool] = lambda _: True, timeout: float = 120
    ) -> HubEvent:
        deadline = time.monotonic() + timeout
        while True:
            for event in self.seen:
                if event.kind == kind and where(event.payload):
                    return event
            self.seen.append(self.arrived.get(timeout=max(0.1, deadline - time.monotonic())))


def test_a_viewer_receives_the_scene_and_the_arm_moving(app: tuple[FastAPI, str]) -> None:
    import sim

    fastapi_app, url = app
    import httpx

    with httpx.Client(base_url=url, headers={"X-API-Key": API_KEY}, timeout=60) as api:
        study = api.post("/api/studies", json={"name": "viewer"}).json()
        body = session_body("human", advice_budget=3, motion="physics", episodes=1)
        session = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    hub = fastapi_app.state.hub
    events = Events()
    subscription = hub.subscribe(session["id"], events.arrived.put)

    participant = SimulatedParticipant(url, session["participant_token"])
    participant.begin()
    reset = events.first("scene_reset")
    names = {body.name for body in reset.payload.bodies}
    assert all(isinstance(b, sim.BodySpec) for b in reset.payload.bodies)
    assert names >= set(reset.payload.poses) and len(names) >= 8
    request = events.first("advice_request")
    assert request.payload.advice_index == 0 and request.payload.observation_png[:4] == b"\x89PNG"

    state = participant.next_request()
    assert participant.advise(state["advice_index"], 0).status_code == 200  # grab
    assert events.first("advice_given").payload == {"advice_index": 0, "action": 0}
    advised = request.payload.global_step
    step = events.first("scene_step", lambda p: p.global_step == advised)
    assert step.payload.action == 0 and step.payload.advised, "a person's advice, animated"
    assert step.payload.frames and all(isinstance(f, sim.MotionFrame) for f in step.payload.frames)
    assert set(step.payload.poses) == set(reset.payload.poses)
    result = events.first("advice_result").payload
    assert (result.advice_index, result.action, result.reward) == (0, 0, step.payload.reward)
    assert events.first("progress", lambda p: p.advice_given >= 1).payload.global_step >= advised

    late: list[HubEvent] = []
    with hub.subscribe(session["id"], late.append, kinds=["scene_reset", "scene_step"]):
        assert [e.kind for e in late][:1] == ["scene_reset"], "a late viewer gets the scene"
    subscription.close()
    asyncio.run(asyncio.sleep(0))
    with httpx.Client(base_url=url, headers={"X-API-Key": API_KEY}, timeout=120) as api:
        assert api.post(f"/api/sessions/{session['id']}/stop").json()["status"] == "stopped"
    participant.close()
