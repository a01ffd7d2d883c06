"""Many participants on a small server: a human session trains after its advice only in
one of the server's trainer slots; the others wait, shown as queued to the researcher and
to the participant alike, and take a slot as one frees: alone (`training_population=1`),
or those of one learner configuration together, as a population in one worker process.
Also the dashboard's report over sessions of different lengths."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.server.live import API_KEY, LiveServer, serving
from tests.server.participant import SimulatedParticipant
from tests.server.scale import EPISODES, session_body, wait_for_status

pytestmark = pytest.mark.slow


@pytest.fixture
def one_trainer(tmp_path: Path) -> Iterator[LiveServer]:
    with serving(tmp_path, max_trainers=1, training_population=1, heartbeat_s=1) as live:
        yield live


@pytest.fixture
def one_slot_for_populations(tmp_path: Path) -> Iterator[LiveServer]:
    with serving(tmp_path, max_trainers=1, training_population=3, heartbeat_s=1) as live:
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


def _curve(participant: SimulatedParticipant) -> dict:
    return participant.client.get("/api/participant/learning-curve").json()


def test_training_after_advice_waits_for_a_free_trainer_slot(one_trainer: LiveServer) -> None:
    with one_trainer.client() as api:
        study = api.post("/api/studies", json={"name": "queue"}).json()
        body = session_body("human", advice_budget=2, episodes=500)
        first, second, third = (
            api.post(f"/api/studies/{study['id']}/sessions", json=body).json() for _ in range(3)
        )
        a = SimulatedParticipant(one_trainer.url, first["participant_token"])
        b = SimulatedParticipant(one_trainer.url, second["participant_token"])
        c = SimulatedParticipant(one_trainer.url, third["participant_token"])
        _advise_all(a, 2)
        _until(lambda: _progress(api, first["id"])["stage"] == "train")
        _advise_all(b, 2)
        _until(lambda: _progress(api, second["id"])["queued"])
        _advise_all(c, 2)
        _until(lambda: _progress(api, third["id"])["queued"])
        assert [_curve(p)["queue_place"] for p in (b, c)] == [1, 2], "each alone: one by one"
        waiting = _progress(api, second["id"])
        assert waiting["status"] == "queued" and waiting["advice_left"] == 0
        assert waiting["queue_place"] == 1
        listed = {s["id"]: s for s in api.get(f"/api/studies/{study['id']}/sessions").json()}
        shown = [(listed[s["id"]]["status"], listed[s["id"]]["queue_place"])
                 for s in (first, second, third)]  # fmt: skip
        assert shown == [("running", None), ("queued", 1), ("queued", 2)], "queued, not running"
        one = api.get(f"/api/sessions/{third['id']}").json()
        assert (one["status"], one["queue_place"]) == ("queued", 2)
        with httpx.Client(base_url=one_trainer.url, timeout=60) as dashboard:
            assert dashboard.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
            rows = {
                s["id"]: s
                for st in dashboard.get("/dashboard/api/overview").json()
                for s in st["sessions"]
            }
        row = rows[third["id"]]  # the page's badge shows the status, its progress the place
        assert (row["status"], row["progress"]["queue_place"]) == ("queued", 2)
        # The participant's own endpoints show what the researcher's do: queued, in place 1
        # (the flag kept for clients that read it).
        own = b.state()
        assert (own["status"], own["queued"], own["queue_place"]) == ("queued", True, 1)
        assert "waits in line" in own["message"]
        curve = _curve(b)
        assert (curve["status"], curve["queued"], curve["queue_place"]) == ("queued", True, 1)
        assert (_curve(c)["status"], c.state()["queue_place"]) == ("queued", 2)
        assert a.state()["status"] == _curve(a)["status"] == "running", "a: in its slot"
        trained = _progress(api, first["id"])["global_step"]
        time.sleep(2.0)
        assert _progress(api, second["id"])["global_step"] == waiting["global_step"], (
            "a queued session does not train"
        )
        assert _progress(api, first["id"])["global_step"] > trained, "the one in its slot does"
        assert not _progress(api, first["id"])["queued"]

        api.post(f"/api/sessions/{first['id']}/stop")
        _until(lambda: not _progress(api, second["id"])["queued"])
        training = api.get(f"/api/sessions/{second['id']}").json()
        assert (training["status"], training["queue_place"]) == ("running", None), "its slot"
        own, curve = b.state(), _curve(b)
        assert (own["status"], own["queued"], own["queue_place"]) == ("running", False, None)
        assert (curve["status"], curve["queued"], curve["queue_place"]) == ("running", False, None)
        assert _progress(api, third["id"])["queue_place"] == 1
        moved = _progress(api, second["id"])["global_step"]
        _until(lambda: _progress(api, second["id"])["global_step"] > moved + 5)
        assert _progress(api, third["id"])["queued"], "training_population=1: one after another"
        assert _curve(c)["queue_place"] == 1
        pids = [api.get(f"/api/sessions/{second['id']}").json()["worker_pid"]]
        api.post(f"/api/sessions/{second['id']}/stop")
        _until(lambda: not _progress(api, third["id"])["queued"])
        pids.append(api.get(f"/api/sessions/{third['id']}").json()["worker_pid"])
        assert None not in pids and pids[0] != pids[1], "each trained in its own worker"
        api.post(f"/api/sessions/{third['id']}/stop")
        for participant in (a, b, c):
            participant.close()


def test_queued_sessions_of_one_configuration_train_together(
    one_slot_for_populations: LiveServer,
) -> None:
    """Three finished sessions queued for the one slot take it together: one worker process
    trains them, each with its own records, progress and status; one stopped stops alone,
    the others train to their end."""
    live = one_slot_for_populations
    with live.client() as api:
        study = api.post("/api/studies", json={"name": "populations"}).json()
        sessions = f"/api/studies/{study['id']}/sessions"
        first = api.post(sessions, json=session_body("human", advice_budget=1, episodes=500))
        first = first.json()
        short = [session_body("human", advice_budget=1, seed=seed) for seed in (21, 22)]
        second, third = (api.post(sessions, json=body).json() for body in short)
        body = session_body("human", advice_budget=1, seed=23, episodes=500)
        fourth = api.post(sessions, json=body).json()
        a, b, c, d = (
            SimulatedParticipant(live.url, s["participant_token"])
            for s in (first, second, third, fourth)
        )
        _advise_all(a, 1)
        _until(lambda: _progress(api, first["id"])["stage"] == "train")
        for participant, session in ((b, second), (c, third), (d, fourth)):
            _advise_all(participant, 1)
            _until(lambda s=session: _progress(api, s["id"])["queued"])
        assert [_curve(p)["queue_place"] for p in (b, c, d)] == [1, 1, 1], "the next slot's"
        alone = api.get(f"/api/sessions/{first['id']}").json()["worker_pid"]

        api.post(f"/api/sessions/{first['id']}/stop")
        _until(lambda: _progress(api, fourth["id"])["episode"] >= 1)
        assert not _progress(api, fourth["id"])["queued"]
        running = [api.get(f"/api/sessions/{s['id']}").json() for s in (second, third, fourth)]
        pids = {row["worker_pid"] for row in running}
        assert len(pids) == 1 and None not in pids and alone not in pids, "one process for three"
        stopped = api.post(f"/api/sessions/{fourth['id']}/stop")
        assert stopped.status_code == 200 and stopped.json()["status"] == "stopped", stopped.text
        rows = [wait_for_status(api, s["id"], {"finished"}) for s in (second, third)]
        rows.append(api.get(f"/api/sessions/{fourth['id']}").json())
        assert rows[2]["status"] == "stopped", "the one stopped stays stopped"
        assert {row["worker_pid"] for row in rows} == {None}, "no worker runs them now"
        together = [row["provenance"][-1]["population"] for row in rows]
        assert [p["population_size"] for p in together] == [3, 3, 3]
        assert sorted(p["population_index"] for p in together) == [0, 1, 2]
        assert [p["seed"] for p in together] == [21, 22, 23], "each agent its own session's"
        for participant, session in ((b, second), (c, third)):
            progress = _progress(api, session["id"])
            assert progress["status"] == "finished" and not progress["queued"]
            assert progress["episode"] == EPISODES and progress["advice_given"] == 1
            curve = _curve(participant)
            assert curve["status"] == "finished"
            assert len(curve["curve"]) == EPISODES, "its own episodes only"
        for participant in (a, b, c, d):
            participant.close()


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
