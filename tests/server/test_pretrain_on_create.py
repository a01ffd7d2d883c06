"""A session made by hand practises from when it is made, by default: its participant, who
may open the link at once and click straight through, does not wait for the robot's random
practice (as an online study's arrivals do not: they get practised sessions from the pools).
`pretrain: false` leaves it to the link."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from study.settings import Settings
from tests.server.live import API_KEY, LiveServer, serving
from tests.server.scale import session_body

pytestmark = pytest.mark.slow


def test_the_default_is_on(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("IDEEPRL_PRETRAIN_ON_CREATE", raising=False)
    monkeypatch.chdir(tmp_path)  # no .env here
    assert Settings(data_dir=tmp_path).pretrain_on_create is True


@pytest.fixture(scope="module")
def practising(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A server as installed: sessions made by hand practise from when they are made."""
    data_dir = tmp_path_factory.mktemp("practising")
    with serving(data_dir, pool_limit=0, pretrain_on_create=True) as live:
        yield live


def _logged_in(browser: httpx.Client) -> httpx.Client:
    login = browser.post("/dashboard/login", data={"key": API_KEY})
    assert login.status_code in (200, 303), login.text
    browser.headers.update({"X-Requested-With": "fetch"})
    return browser


def _status_after(api: httpx.Client, session_id: int, seconds: float = 60) -> str:
    """The session's status once it has had `seconds` to start practising."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        status = str(api.get(f"/api/sessions/{session_id}").json()["status"])
        if status != "created":
            return status
        time.sleep(0.2)
    return "created"


def test_a_new_participant_from_the_dashboard_practises_at_once(practising: LiveServer) -> None:
    with practising.client() as api, httpx.Client(base_url=practising.url) as browser:
        dashboard = _logged_in(browser)
        study = api.post("/api/studies", json={"name": "practice"}).json()["id"]
        path = f"/dashboard/api/studies/{study}/participants"
        made = dashboard.post(path, json={"participant": "P01"})
        assert made.status_code == 201, made.text
        assert _status_after(api, made.json()["id"]) == "running", "its practice started"
        assert api.post(f"/api/sessions/{made.json()['id']}/stop").status_code == 200
        later = dashboard.post(path, json={"participant": "P02", "pretrain": False})
        assert later.status_code == 201, later.text
        assert _status_after(api, later.json()["id"], seconds=3) == "created"


def test_a_human_session_made_through_the_api_practises_at_once(practising: LiveServer) -> None:
    with practising.client() as api:
        study = api.post("/api/studies", json={"name": "practice, API"}).json()["id"]
        path = f"/api/studies/{study}/sessions"
        made = api.post(path, json=session_body("human", advice_budget=3))
        assert made.status_code == 201, made.text
        assert _status_after(api, made.json()["id"]) == "running", "its practice started"
        assert api.post(f"/api/sessions/{made.json()['id']}/stop").status_code == 200
        body = session_body("human", advice_budget=3)
        later = api.post(path, params={"pretrain": "false"}, json=body)
        assert later.status_code == 201, later.text
        assert _status_after(api, later.json()["id"], seconds=3) == "created"


def test_sessions_made_by_the_dozen_start_no_more_workers_than_the_limit(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    """A script making many sessions at once starts a worker for the first
    `pretrain_ahead_limit` only; the rest practise when their links are opened, and a
    session that stops frees its place for the next one made."""
    data_dir = tmp_path_factory.mktemp("ahead")
    with (
        serving(data_dir, pool_limit=0, pretrain_on_create=True, pretrain_ahead_limit=2) as live,
        live.client() as api,
    ):
        study = api.post("/api/studies", json={"name": "many"}).json()["id"]
        path = f"/api/studies/{study}/sessions"
        made = [
            api.post(path, json=session_body("human", advice_budget=3)).json()["id"]
            for _ in range(5)
        ]
        statuses = [_status_after(api, i, seconds=20 if n < 2 else 3) for n, i in enumerate(made)]
        assert statuses == ["running", "running", "created", "created", "created"], statuses
        assert api.post(f"/api/sessions/{made[0]}/stop").status_code == 200
        _status_after(api, made[0])
        deadline = time.monotonic() + 30
        while api.get(f"/api/sessions/{made[0]}").json()["status"] != "stopped":
            assert time.monotonic() < deadline, "the stop took its time"
            time.sleep(0.2)
        another = api.post(path, json=session_body("human", advice_budget=3)).json()["id"]
        assert _status_after(api, another) == "running", "the stopped one's place is free"
        for session_id in (made[1], another):
            assert api.post(f"/api/sessions/{session_id}/stop").status_code == 200
