"""Faults against uninterrupted twins: each case runs a session through a fault and a twin
(same seed, same body) without one; the finished pair must hold the same steps, episodes
and advice, none lost or doubled. Checkpoints come every 2 episodes here, so a resume
rewinds past whole logged episodes."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.server.live import LiveServer, serving
from tests.server.participant import SimulatedParticipant
from tests.server.scale import export, session_body, wait_for_status
from tests.server.test_resume import records

pytestmark = pytest.mark.slow
EPISODES = 5
LONGER = 10
"""Episodes of the several-at-once case: none finishes before all three are killed."""


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    data_dir = tmp_path_factory.mktemp("faults")
    settings = {"checkpoint_every_episodes": 2, "heartbeat_s": 0.5, "stale_after_s": 30}
    with serving(data_dir, **settings) as server:
        yield server


def _episode(api: httpx.Client, session_id: int) -> int:
    return int(api.get(f"/api/sessions/{session_id}/progress").json()["episode"])


def _wait_episode(api: httpx.Client, session_id: int, episode: int) -> None:
    deadline = time.monotonic() + 300
    while _episode(api, session_id) < episode:
        assert time.monotonic() < deadline, f"session {session_id} stalled"
        time.sleep(0.05)


def _kill_worker(api: httpx.Client, session_id: int, wait: bool = True) -> None:
    deadline = time.monotonic() + 60
    while not (pid := api.get(f"/api/sessions/{session_id}").json()["worker_pid"]):
        assert time.monotonic() < deadline
        time.sleep(0.02)
    os.kill(pid, signal.SIGKILL)
    if wait:
        wait_for_status(api, session_id, {"interrupted"}, timeout=60)


def _twins(api: httpx.Client, method: str, **extra: Any) -> tuple[int, dict, dict]:
    study = api.post("/api/studies", json={"name": f"faults-{time.monotonic_ns()}"}).json()["id"]
    body = session_body(method, episodes=EPISODES, **extra)
    faulty = api.post(f"/api/studies/{study}/sessions", json=body).json()
    twin = api.post(f"/api/studies/{study}/sessions", json=body).json()
    assert "id" in faulty, faulty
    return study, faulty, twin


def _same(
    api: httpx.Client, study: int, pairs: list[tuple[int, int]], episodes: int = EPISODES
) -> None:
    for faulty, twin in pairs:
        wait_for_status(api, faulty, {"finished"}, timeout=600)
        wait_for_status(api, twin, {"finished"}, timeout=600)
    files = export(api, study)
    for faulty, twin in pairs:
        got, want = records(files, faulty), records(files, twin)
        assert len([e for e in got["episodes.csv"] if e["stage"] == "train"]) == episodes
        for name in got:
            assert got[name] == want[name], (name, faulty, twin)


@pytest.mark.parametrize("method", ["oracle", "autonomous"])
def test_worker_killed_while_the_server_lives(live: LiveServer, method: str) -> None:
    """Killed mid-run after 3 episodes (checkpoint at 2): the third is logged, rewound and
    written again; also an autonomous session, with no advice to keep."""
    extra = {"advice_budget": 30} if method != "autonomous" else {}
    with live.client() as api:
        study, faulty, twin = _twins(api, method, **extra)
        api.post(f"/api/sessions/{faulty['id']}/start")
        _wait_episode(api, faulty["id"], 3)
        _kill_worker(api, faulty["id"])
        assert api.post(f"/api/sessions/{faulty['id']}/resume").json()["status"] == "running"
        api.post(f"/api/sessions/{twin['id']}/start")
        _same(api, study, [(faulty["id"], twin["id"])])


def test_killed_again_during_its_resume(live: LiveServer) -> None:
    with live.client() as api:
        study, faulty, twin = _twins(api, "oracle", advice_budget=30)
        api.post(f"/api/sessions/{faulty['id']}/start")
        _wait_episode(api, faulty["id"], 1)
        _kill_worker(api, faulty["id"])
        api.post(f"/api/sessions/{faulty['id']}/resume")
        _kill_worker(api, faulty["id"])  # as soon as it has a pid: while it loads and rewinds
        assert api.post(f"/api/sessions/{faulty['id']}/resume").json()["status"] == "running"
        api.post(f"/api/sessions/{twin['id']}/start")
        _same(api, study, [(faulty["id"], twin["id"])])


def test_several_sessions_killed_at_once(live: LiveServer) -> None:
    with live.client() as api:
        study = api.post("/api/studies", json={"name": "several"}).json()["id"]
        pairs = []
        for seed, method in [(1, "oracle"), (2, "random"), (3, "autonomous")]:
            budget = {} if method == "autonomous" else {"advice_budget": 20}
            body = session_body(method, episodes=LONGER, seed=seed, **budget)
            faulty = api.post(f"/api/studies/{study}/sessions", json=body).json()
            twin = api.post(f"/api/studies/{study}/sessions", json=body).json()
            pairs.append((faulty["id"], twin["id"]))
        for faulty, _ in pairs:
            api.post(f"/api/sessions/{faulty}/start")
        for faulty, _ in pairs:  # each killed as soon as it is one episode in
            _wait_episode(api, faulty, 1)
            _kill_worker(api, faulty, wait=False)
        for faulty, _ in pairs:
            wait_for_status(api, faulty, {"interrupted"}, timeout=60)
        for faulty, twin in pairs:
            assert api.post(f"/api/sessions/{faulty}/resume").json()["status"] == "running"
            api.post(f"/api/sessions/{twin}/start")
        _same(api, study, pairs, LONGER)


def test_an_abandoned_human_session_resumed(live: LiveServer) -> None:
    budget, actions = 6, [0, 1, 3, 0, 2, 3]
    with live.client() as api:
        study, faulty, twin = _twins(api, "human", advice_budget=budget)
        # the same run, abandoned after 4 s without advice (the limit is not in the records)
        body = session_body("human", episodes=EPISODES, advice_budget=budget, idle_limit_s=4)
        faulty = api.post(f"/api/studies/{study}/sessions", json=body).json()
        participant = SimulatedParticipant(live.url, faulty["participant_token"])
        participant.begin()  # consent, then the induction's Start
        for index in range(3):
            state = participant.next_request()
            assert participant.advise(state["advice_index"], actions[index]).status_code == 200
        abandoned = wait_for_status(api, faulty["id"], {"abandoned"}, timeout=120)
        assert "idle limit" in abandoned["status_detail"]
        api.post(f"/api/sessions/{faulty['id']}/resume")
        for index in range(3, budget):
            state = participant.next_request()
            assert state["advice_index"] == index
            assert participant.advise(index, actions[index]).status_code == 200
        other = SimulatedParticipant(live.url, twin["participant_token"])
        other.begin()
        for index in range(budget):
            state = other.next_request()
            assert other.advise(state["advice_index"], actions[index]).status_code == 200
        _same(api, study, [(faulty["id"], twin["id"])])
        participant.close()
        other.close()
