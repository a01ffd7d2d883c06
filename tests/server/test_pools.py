"""Pools of pretrained sessions: each condition of an online study keeps sessions made and
practised ahead of arrivals (their seeds and conditions fixed when made); they wait with
their idle limit off, take no place and stay out of the export; an arrival gets one of the
condition the randomization chose, whose idle limit then runs; the pool is topped up."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.server.live import LiveServer, serving
from tests.server.test_online_study import (
    TINY_RUN,
    arrive,
    exported,
    sessions_of,
    table,
    token_of,
)

pytestmark = pytest.mark.slow
IDLE_S = 3.0


@pytest.fixture(scope="module")
def pooled_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    data_dir = tmp_path_factory.mktemp("pools")
    with serving(
        data_dir, heartbeat_s=1, pool_limit=3, pool_every_s=0.5, pool_practising=1
    ) as live:
        yield live


def wait_for(what: str, check: Any, timeout: float = 120) -> Any:
    deadline = time.monotonic() + timeout
    while not (found := check()):
        assert time.monotonic() < deadline, f"never: {what}"
        time.sleep(0.2)
    return found


def ready(server: LiveServer, session: dict[str, Any]) -> bool:
    """The session practised up to its first turn and waits there."""
    token = session["participant_url"].rsplit("/", 1)[1]
    with server.client(key=None, token=token) as client:
        return bool(client.get("/api/participant/readiness").json()["ready"])


def test_an_arrival_takes_a_practised_session_of_its_condition(
    pooled_server: LiveServer, tmp_path: Path
) -> None:
    server = pooled_server
    run = {**TINY_RUN, "seed": 40}
    design = {
        "conditions": {
            "early": {"run": {**run, "strategy": "early"}, "target": 2},
            "alternating": {"run": {**run, "strategy": "alternating"}, "target": 2},
        },
        "pool": 2,
        "idle_limit_s": IDLE_S,
        "panel": {"kind": "prolific"},
    }
    with server.client() as api:
        study = api.post("/api/studies", json={"name": "pools", "design": design}).json()

        def pooled() -> list[dict[str, Any]]:
            return [s for s in sessions_of(api, study) if s["pooled"]]

        practising: list[int] = []  # pooled sessions not at their first turn, each look

        def filled() -> bool:
            sessions = pooled()
            practising.append(sum(not ready(server, s) for s in sessions))
            return len(sessions) == 3 and practising[-1] == 0

        wait_for("3 pooled sessions (the server's limit), practised", filled)
        assert max(practising) == 1, f"one practises at a time, the next after it: {practising}"
        first = pooled()
        assert sorted(s["run"]["seed"] for s in first) == [40, 41, 42], "numbered as made"
        time.sleep(IDLE_S + 2)
        still = pooled()
        assert {s["id"] for s in still} == {s["id"] for s in first}
        assert all(s["status"] == "running" and s["outcome"] is None for s in still), (
            "no idle limit runs in the pool"
        )
        counts = api.get(f"/api/studies/{study['id']}/conditions").json()
        assert all(c["in_progress"] == 0 for c in counts), "the pool takes no place"

        token = token_of(arrive(server, study, "POOL1", "10.9.0.1"))
        mine = next(s for s in sessions_of(api, study) if s["participant_url"].endswith(token))
        assert mine["id"] in {s["id"] for s in first} and not mine["pooled"]
        made = next(s for s in first if s["id"] == mine["id"])
        assert mine["run"] == made["run"], "the run (its seed) as fixed when it was made"
        assert mine["condition"] == made["condition"]
        assert ready(server, mine), "the first turn is there already"
        wait_for(
            "the pool topped up",
            lambda: len(pooled()) == 3 and mine["id"] not in {s["id"] for s in pooled()},
        )
        wait_for(
            "the taken session's idle limit ran from the arrival",
            lambda: api.get(f"/api/sessions/{mine['id']}").json()["outcome"] == "timed_out",
            timeout=60,
        )
        folder = exported(api, study, tmp_path)
    assert [int(r["session_id"]) for r in table(folder, "sessions")] == [mine["id"]]
    assert len(table(folder, "assignments")) == 1

    with server.client() as api:  # the pools' sessions, nobody's yet, end with their study
        kept = [s["id"] for s in sessions_of(api, study) if s["pooled"]]
        assert kept and all(server_has_worker(server, i) for i in kept), "the pool runs"
        gone = api.delete(f"/api/studies/{study['id']}")
        assert gone.status_code == 204, gone.text
        assert api.get(f"/api/studies/{study['id']}").status_code == 404
        assert all(api.get(f"/api/sessions/{i}").status_code == 404 for i in kept)


def server_has_worker(server: LiveServer, session_id: int) -> bool:
    with server.client() as api:
        return api.get(f"/api/sessions/{session_id}").json()["status"] == "running"


def test_the_pools_are_off_at_limit_zero(server: LiveServer, api: httpx.Client) -> None:
    design = {"conditions": {"a": {"run": TINY_RUN}}, "pool": 2, "panel": {"kind": "prolific"}}
    study = api.post("/api/studies", json={"name": "no pools", "design": design}).json()
    time.sleep(3)
    assert sessions_of(api, study) == [], "the shared test server keeps no pools"
