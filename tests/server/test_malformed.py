"""Malformed input gets a 4xx that says what is wrong, never a 500."""

from __future__ import annotations

import uuid

import httpx
import pytest

from tests.server.live import LiveServer
from tests.server.test_access import researcher_routes

BAD_BODIES: list[object] = [
    {"method": "human", "strategy": "importance"},
    None,
    [],
    "text",
    12,
    {"name": None},
    {"name": ""},
    {"name": "x" * 5000},
    {"method": "telepathy"},
    {"method": "oracle", "seed": -1},
    {"method": "oracle", "seed": 2**70},
    {"method": "oracle", "config": {"no_such_field": 1}},
    {"method": "oracle", "config": "lr"},
    {"method": "oracle", "episodes": 0},
    {"method": "oracle", "sort_rule": {"cube/red": "up"}},
    {"method": "oracle", "sort_rule": 7},
    {"method": "agent"},
    {"method": "agent", "advisor_checkpoint": "/no/such/file.pt"},
    {"method": "human", "participant": "../../etc/passwd"},
    {"method": "oracle", "oracle_error_rate": 2},
    {"method": "oracle", "preset": "nope"},
    {"advice_index": -1, "action": 9},
    {"advice_index": 2**80, "action": 0},
    {"unknown": 1},
]
BAD_IDS = ["0", "-1", "abc", "99999999999999999999", "1.5", "%00"]


@pytest.fixture
def study(server: LiveServer) -> int:
    """A fresh study per test (the fuzzing may delete it)."""
    with server.client() as api:
        response = api.post("/api/studies", json={"name": f"malformed-{uuid.uuid4().hex}"})
        assert response.status_code == 201
        return int(response.json()["id"])


@pytest.mark.parametrize(("method", "path"), researcher_routes())
def test_bad_bodies_and_ids_never_give_a_server_error(
    server: LiveServer, study: int, method: str, path: str
) -> None:
    path = path.replace("/1", f"/{study}", 1)
    with server.client() as api:
        for body in BAD_BODIES:
            response = api.request(method, path, json=body)
            assert response.status_code < 500, (method, path, body, response.text)
        raw = api.request(
            method, path, content=b"{not json", headers={"Content-Type": "application/json"}
        )
        assert raw.status_code < 500
        for bad in BAD_IDS:
            response = api.request(method, path.replace(f"/{study}", f"/{bad}", 1), json={})
            assert response.status_code < 500, (method, path, bad, response.text)


def test_invalid_session_bodies_say_which_field_and_why(server: LiveServer, study: int) -> None:
    with server.client() as api:
        response = api.post(f"/api/studies/{study}/sessions", json={"method": "telepathy"})
        assert response.status_code == 422
        [error] = response.json()["detail"]
        assert error["loc"][-1] == "method" and "autonomous" in error["msg"]
        response = api.post(
            f"/api/studies/{study}/sessions", json={"method": "agent", "advisor_checkpoint": "/x"}
        )
        assert response.status_code == 422
        assert response.json()["detail"][0]["loc"] == ["body", "advisor_checkpoint"]
        response = api.post(
            f"/api/studies/{study}/sessions",
            json={"method": "oracle", "advice_budget": 500, "config": {"pretraining_steps": 100}},
        )
        assert response.status_code == 422
        [error] = response.json()["detail"]
        # refused by the server's check or by the learner's config, naming the field either way
        assert error["loc"][-1] in ("advice_budget", "config") and "pretraining" in error["msg"]
        response = api.post(
            f"/api/studies/{study}/sessions", json={"method": "human", "strategy": "importance"}
        )
        assert response.status_code == 422
        assert response.json()["detail"][0]["loc"] == ["body", "strategy"]


def test_participant_endpoints_reject_bad_queries(server: LiveServer) -> None:
    with server.client(key=None, token="forged") as participant:
        for query in ["after=-1", "timeout=1e9", "after=abc"]:
            response = participant.get(f"/api/participant/state?{query}")
            assert response.status_code < 500
    with httpx.Client(base_url=server.url) as anonymous:
        response = anonymous.post("/api/participant/advice", content=b"\x00\xff")
        assert response.status_code < 500
