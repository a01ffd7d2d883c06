"""Consent is a server-side gate: whoever starts a human session, no advice is asked or
taken before its participant consented and finished the induction; consent and decline
are recorded with the exact texts shown, one stored version per distinct text."""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from sqlalchemy import func, select

from study.db.engine import make_engine, make_session_factory
from study.db.models import Step
from tests.server.live import API_KEY, LiveServer, serving
from tests.server.participant import SimulatedParticipant
from tests.server.scale import export, session_body

pytestmark = pytest.mark.slow


def _rows(files: dict[str, bytes], name: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(files[name].decode())))


def _steps_in_database(server: LiveServer, session_id: int) -> int:
    engine = make_engine(server.database_url)
    try:
        with make_session_factory(engine)() as db:
            return int(db.scalar(select(func.count()).where(Step.session_id == session_id)) or 0)
    finally:
        engine.dispose()


@pytest.fixture(scope="module")
def quiet_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A server whose workers' heartbeat (which also flushes) is too slow to store a step
    within the test's wait: only the flush before waiting for advice can."""
    data_dir: Path = tmp_path_factory.mktemp("quiet")
    with serving(data_dir, heartbeat_s=30, stale_after_s=120) as live:
        yield live


@pytest.fixture
def quiet_api(quiet_server: LiveServer) -> Iterator[httpx.Client]:
    with quiet_server.client() as client:
        yield client


def test_a_session_started_by_the_researcher_asks_no_advice_before_consent_and_induction(
    quiet_server: LiveServer, quiet_api: httpx.Client
) -> None:
    server, api = quiet_server, quiet_api
    study = api.post("/api/studies", json={"name": "consent gate"}).json()
    body = session_body("human", advice_budget=3)
    session = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    participant = SimulatedParticipant(server.url, session["participant_token"])
    started = api.post(f"/api/sessions/{session['id']}/start")
    assert started.status_code == 200 and started.json()["status"] == "running"

    # The random pretraining runs to the first advice, then waits for the participant.
    first_turn = body["run"]["config"]["pretraining_steps"] - 3
    deadline = time.monotonic() + 120
    while not (ready := participant.client.get("/api/participant/readiness").json())["ready"]:
        assert time.monotonic() < deadline, ready
        time.sleep(0.2)
    assert ready["steps_before_first_turn"] == first_turn
    time.sleep(1.5)  # long enough for a request to come, were one sent
    state = participant.state()
    assert state["status"] == "running" and not state["advice_wanted"] and not state["ready"]
    assert participant.client.get("/api/participant/readiness").json()["steps_done"] == first_turn
    assert _steps_in_database(server, session["id"]) == first_turn, "flushed before the wait"

    refused = participant.advise(0, 1)
    assert refused.status_code == 409 and "not consented" in refused.json()["detail"]
    early = participant.client.post("/api/participant/start")
    assert early.status_code == 409 and "consent" in early.json()["detail"]

    decision = participant.consent()
    assert decision["consented_at"] and decision["declined_at"] is None
    assert (
        "{advice_budget}" not in decision["texts"]["consent"]
        and "3" in (decision["texts"]["consent"])
    )
    time.sleep(1.0)
    assert not participant.state()["advice_wanted"], "the induction comes before advice"
    assert participant.advise(0, 1).status_code == 409

    assert participant.client.post("/api/participant/start").status_code == 200
    state = participant.next_request(timeout=60)
    assert state["advice_wanted"] and state["advice_index"] == 0 and state["ready"]
    # The request goes out first and the flush overlaps the person's decision: while the
    # worker waits for an answer, the steps before it (the last advised one included)
    # reach the database (the heartbeat's own flush comes every 30 s here).
    for index in (1, 2):
        assert participant.advise(index - 1, 1).status_code == 200
        state = participant.next_request(timeout=60)
        assert state["advice_index"] == index
        deadline = time.monotonic() + 2
        while (stored := _steps_in_database(server, session["id"])) < first_turn + index:
            assert time.monotonic() < deadline, f"advised step {index} not stored in the wait"
            time.sleep(0.05)
        assert stored == first_turn + index, "only the steps before the wait"
        waiting = participant.state()
        assert waiting["advice_wanted"] and waiting["advice_index"] == index

    shown = api.get(f"/api/sessions/{session['id']}").json()
    assert shown["consented_at"] and shown["induction_done_at"] and shown["texts_version"] == 1
    assert shown["consented_at"] <= shown["induction_done_at"]
    api.post(f"/api/sessions/{session['id']}/stop")
    participant.close()


def test_texts_are_versioned_and_a_decline_is_recorded(
    server: LiveServer, api: httpx.Client
) -> None:
    texts = {"consent": "Version one: you advise {advice_budget} times."}
    study = api.post("/api/studies", json={"name": "texts versions", "texts": texts}).json()
    make = f"/api/studies/{study['id']}/sessions"
    body = session_body("human", advice_budget=4)
    first, second, third = (api.post(make, json=body).json() for _ in range(3))

    a = SimulatedParticipant(server.url, first["participant_token"])
    shown_a = a.consent()
    assert shown_a["texts"]["consent"] == "Version one: you advise 4 times."

    edited = {"consent": "Version two, edited after a session ran."}
    assert api.patch(f"/api/studies/{study['id']}", json={"texts": edited}).status_code == 200
    b = SimulatedParticipant(server.url, second["participant_token"])
    shown_b = b.consent()
    assert shown_b["texts"]["consent"] == edited["consent"]
    assert shown_b["texts_version"] != shown_a["texts_version"]
    again = a.client.get("/api/participant/consent").json()
    assert again["texts"]["consent"] == shown_a["texts"]["consent"], "A keeps what A read"

    c = SimulatedParticipant(server.url, third["participant_token"])
    declined = c.consent(agree=False)
    assert declined["declined_at"] and declined["consented_at"] is None
    assert c.client.post("/api/participant/start").status_code == 409
    foreign = c.client.post("/api/participant/consent", json={"agree": True, "texts_version": 99})
    assert foreign.status_code == 422 and "texts_version" in foreign.text

    files = export(api, study["id"])
    versions = _rows(files, "texts_versions.csv")
    assert [v["texts_version"] for v in versions] == ["1", "2"]
    assert versions[0]["consent"] == shown_a["texts"]["consent"]
    assert versions[1]["consent"] == edited["consent"]
    assert len({v["content_hash"] for v in versions}) == 2
    sessions = {int(r["session_id"]): r for r in _rows(files, "sessions.csv")}
    assert sessions[first["id"]]["texts_version"] == "1" and sessions[first["id"]]["consented_at"]
    assert sessions[second["id"]]["texts_version"] == "2"
    assert sessions[third["id"]]["declined_at"] and not sessions[third["id"]]["consented_at"]
    assert sessions[third["id"]]["texts_version"] == "2"
    documented = {(r["file"], r["column"]) for r in _rows(files, "columns.csv")}
    assert ("texts_versions.csv", "consent") in documented
    assert ("advice.csv", "decision_time_s") in documented
    for p in (a, b, c):
        p.close()


def test_the_dashboard_refuses_to_start_a_session_before_consent(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "dashboard gate"}).json()
    session = api.post(
        f"/api/studies/{study['id']}/sessions", json=session_body("human", advice_budget=2)
    ).json()
    with httpx.Client(base_url=server.url, timeout=60) as dashboard:
        assert dashboard.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
        headers = {"X-Requested-With": "test"}
        path = f"/dashboard/api/sessions/{session['id']}/start"
        refused = dashboard.post(path, headers=headers)
        assert refused.status_code == 409 and "consent" in refused.json()["detail"]
        row = next(
            s
            for st in dashboard.get("/dashboard/api/overview").json()
            for s in st["sessions"]
            if s["id"] == session["id"]
        )
        assert row["status"] == "created" and row["progress"]["consented"] is False
        participant = SimulatedParticipant(server.url, session["participant_token"])
        participant.consent()
        assert dashboard.post(path, headers=headers).status_code == 200
    api.post(f"/api/sessions/{session['id']}/stop")
    participant.close()


def test_decision_times_are_validated_and_stored(server: LiveServer, api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "decision time"}).json()
    session = api.post(
        f"/api/studies/{study['id']}/sessions", json=session_body("human", advice_budget=2)
    ).json()
    participant = SimulatedParticipant(server.url, session["participant_token"])
    participant.begin()
    state = participant.next_request()
    post = participant.client.post
    for bad in (-0.5, 1e9, "soon"):
        response = post(
            "/api/participant/advice", json={"advice_index": 0, "action": 1, "decision_time_s": bad}
        )
        assert response.status_code == 422 and "decision_time_s" in response.text, bad
    raw = b'{"advice_index": 0, "action": 1, "decision_time_s": NaN}'
    nan = post("/api/participant/advice", content=raw, headers={"Content-Type": "application/json"})
    assert nan.status_code == 422
    assert state["advice_index"] == 0
    given = post(
        "/api/participant/advice", json={"advice_index": 0, "action": 1, "decision_time_s": 0.75}
    )
    assert given.status_code == 200, given.text
    stored = api.get(f"/api/sessions/{session['id']}/advice").json()
    assert len(stored) == 1 and stored[0]["decision_time_s"] == 0.75
    assert stored[0]["correct_action"] in (0, 1, 2, 3), "the task's correct action, kept"
    api.post(f"/api/sessions/{session['id']}/stop")
    participant.close()
