"""Many participants on a small server: a human session trains after its advice only in
one of the server's trainer slots; the others wait, shown as queued, and take a slot as
one frees. Also the dashboard's report over sessions of different lengths."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.server.live import API_KEY, LiveServer, serving
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body, wait_for_status

pytestmark = pytest.mark.slow


@pytest.fixture
def one_trainer(tmp_path: Path) -> Iterator[LiveServer]:
    with serving(tmp_path, max_trainers=1, heartbeat_s=1) as live:
        yield live


def _advise_all(participant: SimulatedParticipant, budget: int) -> None:
    participant.begin()
    for index in range(budget):
        state = participant.next_request()
        assert state["advice_index"] == index, state
        assert participant.advise(index, index % 4).status_code == 200


def _progress(api: httpx.Client, session_id: int) -> dict:
    return api.get(f"/api/sessions/{session_id}/progress").json()


def _until(check, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.2)


def test_training_after_advice_waits_for_a_free_trainer_slot(one_trainer: LiveServer) -> None:
    with one_trainer.client() as api:
        study = api.post("/api/studies", json={"name": "queue"}).json()
        body = session_body("human", advice_budget=2, episodes=500)
        first, second = (
            api.post(f"/api/studies/{study['id']}/sessions", json=body).json() for _ in range(2)
        )
        a = SimulatedParticipant(one_trainer.url, first["participant_token"])
        b = SimulatedParticipant(one_trainer.url, second["participant_token"])
        _advise_all(a, 2)
        _until(lambda: _progress(api, first["id"])["stage"] == "train")
        _advise_all(b, 2)
        _until(lambda: _progress(api, second["id"])["queued"])
        waiting = _progress(api, second["id"])
        assert waiting["status"] == "running" and waiting["advice_left"] == 0
        assert b.client.get("/api/participant/learning-curve").json()["queued"] is True
        assert b.state()["queued"] is True
        trained = _progress(api, first["id"])["global_step"]
        time.sleep(2.0)
        assert _progress(api, second["id"])["global_step"] == waiting["global_step"], (
            "a queued session does not train"
        )
        assert _progress(api, first["id"])["global_step"] > trained, "the one in its slot does"
        assert not _progress(api, first["id"])["queued"]

        api.post(f"/api/sessions/{first['id']}/stop")
        _until(lambda: not _progress(api, second["id"])["queued"])
        moved = _progress(api, second["id"])["global_step"]
        _until(lambda: _progress(api, second["id"])["global_step"] > moved + 5)
        api.post(f"/api/sessions/{second['id']}/stop")
        a.close()
        b.close()


def test_the_dashboard_report_compares_sessions_of_different_lengths(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "different lengths"}).json()
    ids = []
    for seed, episodes in ((1, 2), (2, 3)):
        body = session_body("autonomous", seed=seed, episodes=episodes)
        ids.append(api.post(f"/api/studies/{study['id']}/sessions", json=body).json()["id"])
        api.post(f"/api/sessions/{ids[-1]}/start")
    for session_id in ids:
        wait_for_status(api, session_id, {"finished"})
    with httpx.Client(base_url=server.url, timeout=120) as dashboard:
        dashboard.post("/dashboard/login", data={"key": API_KEY})
        headers = {"X-Requested-With": "test"}
        path = f"/dashboard/api/studies/{study['id']}/report"
        built = dashboard.post(path, headers=headers)
        assert built.status_code == 200, built.text
        report = built.json()
        assert report["n_episodes"] == 2
        stored = json.loads((server.data_dir / "reports" / f"study-{study['id']}.json").read_text())
        assert stored["created_at"].endswith("Z"), "one timestamp format, on disk too"
        assert any("differ in length" in note and "first 2" in note for note in report["notes"])
        chosen = dashboard.post(path, headers=headers, json={"n_episodes": 1})
        assert chosen.status_code == 200 and chosen.json()["n_episodes"] == 1
        too_many = dashboard.post(path, headers=headers, json={"n_episodes": 3})
        assert too_many.status_code == 409 and "n_episodes" in too_many.json()["detail"]
    plain = api.post(f"/api/studies/{study['id']}/report", json={})
    assert plain.status_code == 409, "the REST API still asks the researcher to choose"
