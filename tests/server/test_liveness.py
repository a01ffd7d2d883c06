"""A session's liveness is its worker's heartbeat, for the server's own workers too: one
that stops beating (SIGSTOP) is killed and its session marked interrupted within the
stale limit; `stop` answers within a bounded time with the real status; a worker that
waits for a person, or is paused, keeps beating and is left alone."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.server.live import LiveServer, serving
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body, wait_for_status

pytestmark = pytest.mark.slow
STALE_S = 12.0


@pytest.fixture(scope="module")
def stale_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    data_dir = tmp_path_factory.mktemp("liveness")
    with serving(data_dir, heartbeat_s=1, stale_after_s=STALE_S) as live:
        yield live


def _alive(pid: int) -> bool:
    """Running (not a zombie nor gone)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def _gone(pid: int, within: float = 10.0) -> bool:
    deadline = time.monotonic() + within
    while _alive(pid):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.1)
    return True


def _running(api: httpx.Client, study: int) -> dict:
    body = session_body("random", advice_budget=10, episodes=500)
    session = api.post(f"/api/studies/{study}/sessions", json=body).json()
    api.post(f"/api/sessions/{session['id']}/start")
    deadline = time.monotonic() + 120
    while True:
        found = api.get(f"/api/sessions/{session['id']}").json()
        progress = api.get(f"/api/sessions/{session['id']}/progress").json()
        if found["worker_pid"] and progress["global_step"] > 0:
            return found
        assert time.monotonic() < deadline, "the session did not start"
        time.sleep(0.2)


def test_a_stopped_worker_is_killed_and_its_session_interrupted(
    stale_server: LiveServer,
) -> None:
    with stale_server.client() as api:
        study = api.post("/api/studies", json={"name": "sigstop"}).json()["id"]
        session = _running(api, study)
        pid = session["worker_pid"]
        os.kill(pid, signal.SIGSTOP)
        stopped_at = time.monotonic()
        try:
            interrupted = wait_for_status(api, session["id"], {"interrupted"}, timeout=60)
            took = time.monotonic() - stopped_at
            assert _gone(pid), "the hung worker was killed"
        finally:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        print(f"\nSIGSTOPped worker noticed after {took:.1f} s (stale limit {STALE_S:.0f} s)")
        assert took < STALE_S + 5, f"noticed after {took:.0f} s"
        assert "stopped marking itself alive" in interrupted["status_detail"]
        resumed = api.post(f"/api/sessions/{session['id']}/resume")
        assert resumed.status_code == 200 and resumed.json()["status"] == "running"
        assert api.post(f"/api/sessions/{session['id']}/stop").json()["status"] == "stopped"


def test_stop_answers_within_the_limit_with_the_real_status(stale_server: LiveServer) -> None:
    with stale_server.client() as api:
        study = api.post("/api/studies", json={"name": "stop-hung"}).json()["id"]
        session = _running(api, study)
        pid = session["worker_pid"]
        os.kill(pid, signal.SIGSTOP)
        started = time.monotonic()
        try:
            response = api.post(f"/api/sessions/{session['id']}/stop")
            took = time.monotonic() - started
            assert _gone(pid)
        finally:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        print(f"\nstop of a SIGSTOPped worker answered after {took:.1f} s")
        assert response.status_code == 200
        body = response.json()
        assert took < STALE_S + 5
        assert body["status"] == "stopped", body  # what was asked, even if it hung
        assert body["status"] == api.get(f"/api/sessions/{session['id']}").json()["status"]


def test_waiting_for_advice_or_paused_keeps_the_worker_alive(stale_server: LiveServer) -> None:
    with stale_server.client() as api:
        study = api.post("/api/studies", json={"name": "patient"}).json()["id"]
        body = session_body("human", advice_budget=2, episodes=1)
        human = api.post(f"/api/studies/{study}/sessions", json=body).json()
        participant = SimulatedParticipant(stale_server.url, human["participant_token"])
        participant.begin()  # consent, then the induction's Start
        assert participant.next_request()["advice_index"] == 0
        paused = _running(api, study)
        assert api.post(f"/api/sessions/{paused['id']}/pause").json()["status"] == "paused"
        time.sleep(STALE_S + 4)
        assert api.get(f"/api/sessions/{human['id']}").json()["status"] == "running"
        assert api.get(f"/api/sessions/{paused['id']}").json()["status"] == "paused"
        for index in range(2):
            state = participant.next_request() if index else {"advice_index": 0}
            assert state["advice_index"] == index
            assert participant.advise(index, 0).status_code == 200
        wait_for_status(api, human["id"], {"finished"})
        participant.close()
        assert api.post(f"/api/sessions/{paused['id']}/stop").json()["status"] == "stopped"


def test_a_visitor_who_never_consents_holds_no_worker_for_long(stale_server: LiveServer) -> None:
    """Opening the link starts the pretraining; waiting for the participant, the worker
    keeps beating past the stale limit, then abandons after the idle limit and exits; when
    the participant comes back, the session resumes by itself and asks for advice."""
    idle_limit = STALE_S + 8
    with stale_server.client() as api:
        study = api.post("/api/studies", json={"name": "no-show"}).json()["id"]
        body = session_body("human", advice_budget=2, episodes=1, idle_limit_s=idle_limit)
        human = api.post(f"/api/studies/{study}/sessions", json=body).json()
        participant = SimulatedParticipant(stale_server.url, human["participant_token"])
        deadline = time.monotonic() + 120
        while not participant.client.get("/api/participant/readiness").json()["ready"]:
            assert time.monotonic() < deadline, "the pretraining never reached the first turn"
            time.sleep(0.2)
        waiting_since = time.monotonic()
        pid = api.get(f"/api/sessions/{human['id']}").json()["worker_pid"]
        time.sleep(STALE_S + 2)
        assert api.get(f"/api/sessions/{human['id']}").json()["status"] == "running"
        abandoned = wait_for_status(api, human["id"], {"abandoned"}, timeout=60)
        assert time.monotonic() - waiting_since >= idle_limit - 1
        assert abandoned["status_detail"].startswith("the participant did not consent")
        assert _gone(pid), "the abandoned worker exited"
        participant.begin()  # they come back: consent, then the induction's Start
        for index in range(2):
            state = participant.next_request()
            assert state["advice_index"] == index
            assert participant.advise(index, 1).status_code == 200
        wait_for_status(api, human["id"], {"finished"})
        assert api.get(f"/api/sessions/{human['id']}/progress").json()["advice_given"] == 2
        participant.close()
