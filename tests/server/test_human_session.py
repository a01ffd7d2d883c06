"""A human session driven through the participant endpoints, as a page would."""

from __future__ import annotations

import base64

import httpx
import pytest

from tests.server.live import API_KEY, LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import decode_png, session_body, wait_for_status

pytestmark = pytest.mark.slow
BUDGET = 100


def test_a_participant_gives_100_advice_each_stored_once_and_the_101st_is_refused(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "human advice"}).json()
    body = session_body("human", advice_budget=BUDGET, participant="P01")
    body["run"]["config"]["pretraining_steps"] = BUDGET + 20
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    assert created["run"]["motion"] == "fast" and created["participant"] == "P01"
    assert created["participant_url"].endswith("/p/" + created["participant_token"])
    participant = SimulatedParticipant(server.url, created["participant_token"])

    assert participant.state()["status"] == "created"
    started = participant.begin()
    assert started.status_code == 200 and started.json()["status"] == "running"

    for index in range(BUDGET):
        state = participant.next_request()
        assert state["advice_wanted"] and state["advice_index"] == index, state
        assert state["advice_left"] == BUDGET - index
        image = decode_png(base64.b64decode(state["observation_png"]))
        assert image.shape == (64, 64, 3)
        action = index % 4
        if index == 3:
            wrong = participant.advise(index + 1, action)
            assert wrong.status_code == 409 and f"advice {index} is wanted" in wrong.text
            bad = participant.advise(index, 7)
            assert bad.status_code == 422 and "action" in bad.text
        receipt = participant.advise(index, action, wait=10)
        assert receipt.status_code == 200, receipt.text
        assert receipt.json()["duplicate"] is False
        if index % 10 == 0:
            duplicate = participant.advise(index, action).json()
            assert duplicate["duplicate"] is True
            changed = participant.advise(index, (action + 1) % 4)
            assert changed.status_code == 409 and "cannot be changed" in changed.text

    over = participant.advise(BUDGET, 0)
    assert over.status_code == 409
    assert f"budget of {BUDGET} is spent" in over.json()["detail"]

    state = participant.state()
    assert state["advice_left"] == 0 and state["advice_given"] == BUDGET
    assert [h["advice_index"] for h in state["history"]] == list(range(BUDGET - 10, BUDGET))

    stored = api.get(f"/api/sessions/{created['id']}/advice").json()
    assert [a["advice_index"] for a in stored] == list(range(BUDGET))
    assert [a["action"] for a in stored] == [i % 4 for i in range(BUDGET)]
    assert all(a["advisor"] == "human" and a["response_time_s"] > 0 for a in stored)
    assert all(a["greedy_action"] in range(4) for a in stored), "complete once written"
    png = api.get(f"/api/sessions/{created['id']}/advice/42.png")
    assert png.headers["content-type"] == "image/png"
    assert decode_png(png.content).shape == (64, 64, 3)

    wait_for_status(api, created["id"], {"finished"})
    assert participant.advise(BUDGET, 0).status_code == 409
    assert api.get(f"/api/sessions/{created['id']}/advice").json() == stored, "never updated"
    participant.close()


def test_a_token_reaches_only_its_own_session(server: LiveServer, api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "isolation"}).json()
    body = session_body("human", advice_budget=5)
    first = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    second = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    assert first["participant_token"] != second["participant_token"]
    a = SimulatedParticipant(server.url, first["participant_token"])
    b = SimulatedParticipant(server.url, second["participant_token"])
    a.begin()
    state = a.next_request()
    assert state["session_id"] == first["id"]
    assert a.advise(0, 1).status_code == 200
    assert b.state()["session_id"] == second["id"] and b.state()["status"] == "created"
    assert b.advise(0, 1).status_code == 409
    assert api.get(f"/api/sessions/{second['id']}/advice").json() == []
    as_researcher = a.client.get(f"/api/sessions/{second['id']}")
    assert as_researcher.status_code == 401
    api.post(f"/api/sessions/{first['id']}/stop")
    a.close()
    b.close()


def test_people_made_by_hand_get_a_seed_each_unless_the_run_gives_one(
    server: LiveServer, api: httpx.Client
) -> None:
    """Each participant's learner differs (its first weights, its random practice), as an
    online arrival's does: a human run without a seed takes the study's next number, on the
    REST API and the dashboard alike; a run that gives its seed keeps it."""
    study = api.post("/api/studies", json={"name": "seeds by hand"}).json()["id"]
    made = [
        api.post(f"/api/studies/{study}/sessions", json=body).json()["run"]["seed"]
        for body in (
            {"run": {"method": "human"}, "participant": "P01"},
            {"run": {"method": "human"}, "participant": "P02"},
            {"run": {"method": "human", "seed": 7}, "participant": "P03"},
        )
    ]
    assert made == [0, 1, 7], made
    with httpx.Client(base_url=server.url, headers={"X-Requested-With": "test"}) as browser:
        assert browser.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
        created = browser.post(f"/dashboard/api/studies/{study}/participants", json={})
        assert created.status_code == 201, created.text
    seed = api.get(f"/api/sessions/{created.json()['id']}").json()["run"]["seed"]
    assert seed == 2, "the dashboard's participant: the next number"
