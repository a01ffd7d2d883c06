"""Researcher commands (pause, resume, stop) and the idle limit of human sessions."""

from __future__ import annotations

import os
import signal
import time

import httpx
import pytest

from tests.server.live import LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body, wait_for_status

pytestmark = pytest.mark.slow


def step_of(api: httpx.Client, session_id: int) -> int:
    return int(api.get(f"/api/sessions/{session_id}/progress").json()["global_step"])


def wait_step(api: httpx.Client, session_id: int, beyond: int) -> int:
    deadline = time.monotonic() + 120
    while (step := step_of(api, session_id)) <= beyond:
        assert time.monotonic() < deadline, f"session {session_id} made no progress"
        time.sleep(0.1)
    return step


def test_pause_resume_stop_and_resume_again(server: LiveServer, api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "lifecycle"}).json()
    body = session_body("autonomous", episodes=500)
    session = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    sid = session["id"]
    assert api.post(f"/api/sessions/{sid}/pause").status_code == 409  # not running yet
    api.post(f"/api/sessions/{sid}/start")
    wait_step(api, sid, 0)

    paused = api.post(f"/api/sessions/{sid}/pause").json()
    assert paused["status"] == "paused"
    held = step_of(api, sid)
    assert paused["checkpoint_step"] == held, "pausing checkpoints where it stands"
    time.sleep(1.0)
    assert step_of(api, sid) == held

    assert api.post(f"/api/sessions/{sid}/resume").json()["status"] == "running"
    moved = wait_step(api, sid, held)

    stopped = api.post(f"/api/sessions/{sid}/stop").json()
    assert stopped["status"] == "stopped" and stopped["checkpoint_step"] >= moved
    assert "resume" in api.post(f"/api/sessions/{sid}/start").json()["detail"]
    assert api.post(f"/api/sessions/{sid}/pause").status_code == 409

    assert api.post(f"/api/sessions/{sid}/resume").json()["status"] == "running"
    wait_step(api, sid, stopped["checkpoint_step"])
    assert api.post(f"/api/sessions/{sid}/stop").json()["status"] == "stopped"
    steps = api.get(f"/api/sessions/{sid}/episodes", params={"stage": "all"}).json()
    starts = [e["first_global_step"] for e in steps]
    assert starts == sorted(set(starts)), "no episode logged twice across pause and resume"


def test_an_idle_participant_abandons_the_session_which_resumes(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "idle"}).json()
    body = session_body("human", advice_budget=3, idle_limit_s=2, episodes=1)
    session = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    participant = SimulatedParticipant(server.url, session["participant_token"])
    participant.begin()
    assert participant.next_request()["advice_index"] == 0

    abandoned = wait_for_status(api, session["id"], {"abandoned"}, timeout=60)
    assert "idle limit" in abandoned["status_detail"]
    state = participant.state()
    assert state["status"] == "abandoned" and not state["advice_wanted"]
    assert "resume" in state["message"]
    assert participant.advise(0, 1).status_code == 409

    api.post(f"/api/sessions/{session['id']}/resume")
    for index in range(3):
        state = participant.next_request()
        assert state["advice_index"] == index
        assert participant.advise(index, 0).status_code == 200
    wait_for_status(api, session["id"], {"finished"})
    participant.close()


def test_a_killed_worker_is_noticed_at_once(server: LiveServer, api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "killed worker"}).json()
    session = api.post(
        f"/api/studies/{study['id']}/sessions",
        json=session_body("random", advice_budget=20, episodes=500),
    ).json()
    api.post(f"/api/sessions/{session['id']}/start")
    wait_step(api, session["id"], 0)
    os.kill(api.get(f"/api/sessions/{session['id']}").json()["worker_pid"], signal.SIGKILL)
    interrupted = wait_for_status(api, session["id"], {"interrupted"}, timeout=30)
    assert "exited unexpectedly (exit code -9)" in interrupted["status_detail"]
    assert api.post(f"/api/sessions/{session['id']}/stop").json()["status"] == "stopped"
