"""The viewer's feed: scene and progress events flow from a worker to the web process's
hub, as issue 5's viser view will subscribe to them."""

from __future__ import annotations

import asyncio
import contextlib
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


@contextlib.contextmanager
def _served(tmp_path: Path, **settings: Any) -> Iterator[tuple[FastAPI, str]]:
    """The app served by uvicorn on loopback, in this process, so the test can reach its hub."""
    with fresh_database(tmp_path) as url:
        port = free_port()
        app = create_app(
            Settings(database_url=url, api_key=API_KEY, data_dir=tmp_path, port=port, **settings)
        )
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


@pytest.fixture
def app(tmp_path: Path) -> Iterator[tuple[FastAPI, str]]:
    with _served(tmp_path) as served:
        yield served


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


@pytest.fixture
def one_slot_app(tmp_path: Path) -> Iterator[tuple[FastAPI, str]]:
    """As `app`, with one trainer slot that queued sessions share as a population."""
    with _served(tmp_path, max_trainers=1, training_population=2, heartbeat_s=1) as served:
        yield served


def test_a_viewer_sees_a_session_train_in_a_population(
    one_slot_app: tuple[FastAPI, str],
) -> None:
    """Two finished sessions train together in one worker (issue "The participant's first
    minutes"): the page watching one before they moved there keeps its scene, and a page
    opened on the other once it trains there gets its scene; each sees its own steps."""
    import httpx

    fastapi_app, url = one_slot_app
    hub = fastapi_app.state.hub
    with httpx.Client(base_url=url, headers={"X-API-Key": API_KEY}, timeout=60) as api:
        study = api.post("/api/studies", json={"name": "population view"}).json()
        path = f"/api/studies/{study['id']}/sessions"
        ids, participants = [], []
        for seed in (20, 21, 22):
            body = session_body("human", advice_budget=1, seed=seed, episodes=500)
            created = api.post(path, json=body).json()
            ids.append(created["id"])
            participants.append(SimulatedParticipant(url, created["participant_token"]))

        def progress(session_id: int) -> dict:
            return api.get(f"/api/sessions/{session_id}/progress").json()

        def until(check: Callable[[], bool], timeout: float = 120) -> None:
            deadline = time.monotonic() + timeout
            while not check():
                assert time.monotonic() < deadline, "timed out"
                time.sleep(0.2)

        for participant, session_id in zip(participants, ids, strict=True):
            participant.begin()
            state = participant.next_request()
            assert participant.advise(state["advice_index"], 1).status_code == 200
            if session_id == ids[0]:
                until(lambda: progress(ids[0])["stage"] == "train")
            else:
                until(lambda s=session_id: progress(s)["queued"])
        before = Events()
        watching_before = hub.subscribe(ids[1], before.arrived.put)
        api.post(f"/api/sessions/{ids[0]}/stop")
        until(lambda: not any(progress(s)["queued"] for s in ids[1:]))

        def workers() -> set[int]:
            return {api.get(f"/api/sessions/{s}").json()["worker_pid"] for s in ids[1:]}

        until(lambda: len(workers()) == 1)  # the two train in one population
        moved = max(progress(s)["global_step"] for s in ids[1:])
        later = Events()
        watching_later = hub.subscribe(ids[2], later.arrived.put)
        for events in (before, later):
            step = events.first("scene_step", lambda p: p.global_step > moved + 3, timeout=60)
            assert step.payload.poses, "the scene's bodies where they are"
        for session_id in ids[1:]:
            assert api.post(f"/api/sessions/{session_id}/stop").json()["status"] == "stopped"
        watching_before.close()
        watching_later.close()
    for participant in participants:
        participant.close()
