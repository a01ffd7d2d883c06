"""A session's `worker_pid` names the process that runs it now: null once its worker has
exited, whether the participant declined or the researcher stopped it."""

from __future__ import annotations

import os
import time
from typing import Any

import httpx
import pytest

from tests.server.live import LiveServer
from tests.server.scale import session_body, wait_for_status
from tests.server.test_online_study import arrive, make_study, sessions_of, token_of

pytestmark = pytest.mark.slow


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _running_worker(api: httpx.Client, session_id: int, timeout: float = 120) -> int:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        pid = api.get(f"/api/sessions/{session_id}").json()["worker_pid"]
        if pid:
            return int(pid)
        time.sleep(0.2)
    raise AssertionError(f"session {session_id} got no worker")


def _ended(api: httpx.Client, session_id: int, pid: int, timeout: float = 60) -> dict[str, Any]:
    """The session once its worker process has exited."""
    deadline = time.monotonic() + timeout
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(pid), f"worker {pid} still runs"
    return dict(api.get(f"/api/sessions/{session_id}").json())


def test_worker_pid_is_null_once_a_declined_or_stopped_session_s_worker_exited(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "worker pid")
    token = token_of(arrive(server, study, "W1", "10.9.1.1"))
    with httpx.Client(base_url=server.url, follow_redirects=True) as browser:
        assert browser.get(f"/p/{token}").status_code == 200  # its consent page: practice
    (declining,) = sessions_of(api, study)
    pid = _running_worker(api, declining["id"])
    with server.client(key=None, token=token) as participant:
        declined = participant.post("/api/participant/consent", json={"agree": False})
        assert declined.status_code == 200, declined.text
    wait_for_status(api, declining["id"], {"declined"})
    assert _ended(api, declining["id"], pid)["worker_pid"] is None

    lab = api.post("/api/studies", json={"name": "worker pid, lab"}).json()["id"]
    made = api.post(
        f"/api/studies/{lab}/sessions",
        params={"pretrain": "true"},
        json=session_body("human", advice_budget=3),
    )
    assert made.status_code == 201, made.text
    stopping = made.json()
    pid = _running_worker(api, stopping["id"])
    assert api.post(f"/api/sessions/{stopping['id']}/stop").status_code == 200
    assert _ended(api, stopping["id"], pid)["worker_pid"] is None
