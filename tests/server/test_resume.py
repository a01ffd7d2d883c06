"""Kill a worker, or the whole server, in the middle of a session; restart; resume: the
finished session holds exactly the records of an uninterrupted one with the same seed."""

from __future__ import annotations

import csv
import io
import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.server.live import LiveServer, fresh_database
from tests.server.participant import SimulatedParticipant
from tests.server.scale import NONDETERMINISTIC, export, session_body, wait_for_status

pytestmark = pytest.mark.slow
EPISODES = 3


@pytest.fixture
def live(tmp_path: Path) -> Iterator[LiveServer]:
    with fresh_database(tmp_path) as url:
        server = LiveServer(
            tmp_path, url, checkpoint_every_episodes=1, heartbeat_s=0.5, stale_after_s=3
        ).start()
        try:
            yield server
        finally:
            server.stop()


def records(files: dict[str, bytes], session_id: int) -> dict[str, list[dict[str, Any]]]:
    out = {}
    for name in ("steps.csv", "episodes.csv", "advice.csv"):
        rows = csv.DictReader(io.StringIO(files[name].decode()))
        out[name] = [
            {
                k: v
                for k, v in r.items()
                if k not in NONDETERMINISTIC | {"session_id", "observation_file"}
            }
            for r in rows
            if int(r["session_id"]) == session_id
        ]
    return out


def wait_progress(api: httpx.Client, session_id: int, episode: int) -> None:
    deadline = time.monotonic() + 180
    while api.get(f"/api/sessions/{session_id}/progress").json()["episode"] < episode:
        assert time.monotonic() < deadline
        time.sleep(0.05)


def test_a_session_killed_with_its_server_resumes_to_exactly_the_uninterrupted_records(
    live: LiveServer,
) -> None:
    with live.client() as api:
        study = api.post("/api/studies", json={"name": "crash"}).json()
        body = session_body("oracle", advice_budget=30, episodes=EPISODES)
        crashed = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
        reference = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()

        api.post(f"/api/sessions/{crashed['id']}/start")
        wait_progress(api, crashed["id"], 2)
        pid = api.get(f"/api/sessions/{crashed['id']}").json()["worker_pid"]
    os.kill(pid, signal.SIGKILL)  # worker and server at once: nobody marks the session
    live.stop(kill=True)
    live.start()
    with live.client() as api:
        interrupted = wait_for_status(api, crashed["id"], {"interrupted"}, timeout=30)
        assert "resume" in interrupted["status_detail"] and interrupted["checkpoint_step"] > 0
        assert api.post(f"/api/sessions/{crashed['id']}/resume").json()["status"] == "running"
        api.post(f"/api/sessions/{reference['id']}/start")
        wait_for_status(api, crashed["id"], {"finished"})
        wait_for_status(api, reference["id"], {"finished"})
        files = export(api, study["id"])
    resumed, uninterrupted = records(files, crashed["id"]), records(files, reference["id"])
    assert len([e for e in resumed["episodes.csv"] if e["stage"] == "train"]) == EPISODES
    for name in resumed:
        assert resumed[name] == uninterrupted[name], name


def test_a_human_session_survives_a_server_crash_without_asking_again(live: LiveServer) -> None:
    budget, before_crash = 10, 6
    actions = [0, 1, 3, 0, 2, 3, 0, 1, 3, 0]
    with live.client() as api:
        study = api.post("/api/studies", json={"name": "human crash"}).json()
        body = session_body("human", advice_budget=budget, episodes=1)
        crashed = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
        reference = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
        participant = SimulatedParticipant(live.url, crashed["participant_token"])
        participant.begin()
        for index in range(before_crash):
            state = participant.next_request()
            assert participant.advise(state["advice_index"], actions[index]).status_code == 200
        worker = api.get(f"/api/sessions/{crashed['id']}").json()["worker_pid"]

    live.stop(kill=True)
    deadline = time.monotonic() + 30
    while _alive(worker):
        assert time.monotonic() < deadline, "the worker outlived its server"
        time.sleep(0.1)
    live.start()
    with live.client() as api:
        assert wait_for_status(api, crashed["id"], {"interrupted"}, timeout=30)
        api.post(f"/api/sessions/{crashed['id']}/resume")
        state = participant.next_request()
        assert state["advice_index"] == before_crash and state["advice_given"] == before_crash
        for index in range(before_crash, budget):
            state = participant.next_request()
            assert participant.advise(state["advice_index"], actions[index]).status_code == 200
        other = SimulatedParticipant(live.url, reference["participant_token"])
        other.begin()
        for index in range(budget):
            state = other.next_request()
            assert other.advise(state["advice_index"], actions[index]).status_code == 200
        wait_for_status(api, crashed["id"], {"finished"})
        wait_for_status(api, reference["id"], {"finished"})
        files = export(api, study["id"])
    resumed, uninterrupted = records(files, crashed["id"]), records(files, reference["id"])
    assert len(resumed["advice.csv"]) == budget
    for name in resumed:
        assert resumed[name] == uninterrupted[name], name
    participant.close()
    other.close()


def test_a_rating_session_survives_a_server_crash_without_asking_again(live: LiveServer) -> None:
    """Evaluative feedback: the ratings given before the crash are replayed to the learner,
    never asked again, and the resumed run's records equal an uninterrupted one's."""
    budget, before_crash = 6, 3
    ratings = ["good", "bad", "good", "bad", "bad", "good"]
    with live.client() as api:
        study = api.post("/api/studies", json={"name": "rating crash"}).json()
        body = session_body("human", advice_budget=budget, episodes=1, feedback="evaluative")
        crashed = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
        reference = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
        participant = SimulatedParticipant(live.url, crashed["participant_token"])
        participant.begin()
        for index in range(before_crash):
            assert rate(participant, ratings[index]) == index
        worker = api.get(f"/api/sessions/{crashed['id']}").json()["worker_pid"]

    live.stop(kill=True)
    deadline = time.monotonic() + 30
    while _alive(worker):
        assert time.monotonic() < deadline, "the worker outlived its server"
        time.sleep(0.1)
    live.start()
    with live.client() as api:
        assert wait_for_status(api, crashed["id"], {"interrupted"}, timeout=30)
        api.post(f"/api/sessions/{crashed['id']}/resume")
        participant.version = None
        state = participant.next_request()
        assert state["advice_index"] == before_crash and state["advice_given"] == before_crash
        for index in range(before_crash, budget):
            assert rate(participant, ratings[index]) == index
        other = SimulatedParticipant(live.url, reference["participant_token"])
        other.begin()
        for index in range(budget):
            assert rate(other, ratings[index]) == index
        wait_for_status(api, crashed["id"], {"finished"})
        wait_for_status(api, reference["id"], {"finished"})
        files = export(api, study["id"])
    resumed, uninterrupted = records(files, crashed["id"]), records(files, reference["id"])
    for name in resumed:
        assert resumed[name] == uninterrupted[name], name
    judged = list(csv.DictReader(io.StringIO(files["feedback.csv"].decode())))
    for session in (crashed, reference):
        mine = [r for r in judged if r["session_id"] == str(session["id"])]
        assert [r["judgement"] for r in mine] == ["1.0" if r == "good" else "-1.0" for r in ratings]
    participant.close()
    other.close()


def rate(participant: SimulatedParticipant, rating: str) -> int:
    """Rate the next turn's move; the turn's index."""
    state = participant.next_request()
    assert state["rated_action"] is not None, state
    index = state["advice_index"]
    response = participant.client.post(
        "/api/participant/rating",
        params={"wait": 10},
        json={"advice_index": index, "rating": rating},
    )
    assert response.status_code == 200, response.text
    participant.version = response.json()["version"]
    participant.pending = response.json()["state"]
    return int(index)


def test_a_restart_resumes_a_participants_session_by_itself(live: LiveServer) -> None:
    """An update or `systemctl restart` in the middle of a visit: the participant goes on
    where they were, with nobody there to resume their session; a machine session stays
    for whoever started it, and a session the researcher paused stays for them."""
    given = 3
    with live.client() as api:
        study = api.post("/api/studies", json={"name": "restart"}).json()
        human, paused = (
            api.post(
                f"/api/studies/{study['id']}/sessions",
                json=session_body("human", advice_budget=10, episodes=1),
            ).json()
            for _ in range(2)
        )
        machine = api.post(
            f"/api/studies/{study['id']}/sessions",
            json=session_body("oracle", advice_budget=30, episodes=200),
        ).json()
        api.post(f"/api/sessions/{machine['id']}/start")
        participant = SimulatedParticipant(live.url, human["participant_token"])
        participant.begin()
        for index in range(given):
            state = participant.next_request()
            assert participant.advise(state["advice_index"], index % 4).status_code == 200
        assert participant.next_request()["advice_index"] == given
        waiting = SimulatedParticipant(live.url, paused["participant_token"])
        waiting.begin()
        assert waiting.next_request()["advice_wanted"]
        assert api.post(f"/api/sessions/{paused['id']}/pause").status_code == 200
        assert api.get(f"/api/sessions/{machine['id']}").json()["status"] == "running"

    live.stop()  # SIGINT, as systemd's stop sends SIGTERM: the server shuts down in order
    live.start()
    state = participant.next_request(timeout=60)
    assert (state["status"], state["advice_wanted"]) == ("running", True), state
    assert (state["advice_index"], state["advice_given"]) == (given, given)
    with live.client() as api:
        stayed = [api.get(f"/api/sessions/{s['id']}").json() for s in (machine, paused)]
    assert [s["status"] for s in stayed] == ["interrupted", "interrupted"], stayed
    assert "shut down in order" in stayed[0]["status_detail"]
    assert "paused" in stayed[1]["status_detail"]
    participant.close()
    waiting.close()


def _alive(pid: int) -> bool:
    """Running (a zombie nobody has reaped yet counts as gone)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "\nState:\tZ" not in status
