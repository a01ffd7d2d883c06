"""A person advising a vector task (CartPole-v1, defined in the tests): the page shows the
environment's rendered frame, and each advice stores the vector the learner saw with it."""

from __future__ import annotations

import base64

import httpx
import numpy as np
import pytest

from study.services.observations import decode_png, observation_of
from tests.server.live import LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body, wait_for_status

pytestmark = pytest.mark.slow
CARTPOLE = "tests.tasks.cartpole:cartpole_task"


def test_a_person_sees_the_carts_frames_and_their_advice_keeps_its_vector(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "cartpole people"}).json()
    body = session_body("human", task=CARTPOLE, advice_budget=2)
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    assert created["run"]["task"] == CARTPOLE, created
    participant = SimulatedParticipant(server.url, created["participant_token"])
    assert participant.begin().status_code == 200
    seen = []
    for index in range(2):
        state = participant.next_request()
        assert state["advice_index"] == index and state["action_names"] == [
            "push left",
            "push right",
        ]
        frame = decode_png(base64.b64decode(state["frame_png"]))
        assert frame.shape == (400, 600, 3) and len(np.unique(frame.reshape(-1, 3), axis=0)) > 2
        observation = base64.b64decode(state["observation_png"])
        vector = observation_of(observation)
        assert vector.shape == (4,) and np.array_equal(decode_png(observation), frame)
        seen.append(vector)
        assert participant.advise(index, index % 2, wait=10).status_code == 200
    wait_for_status(api, created["id"], {"finished"})
    for index, vector in enumerate(seen):
        stored = api.get(f"/api/sessions/{created['id']}/advice/{index}.png")
        assert stored.status_code == 200, stored.text
        assert np.array_equal(observation_of(stored.content), vector)
