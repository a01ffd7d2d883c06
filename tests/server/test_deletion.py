"""Deletion that deletes: a session's or a study's rows, checkpoints, report and exports
go; a running session is refused; ids are never given again, so nothing of a deleted
study shows under a new one. Also what a finished session keeps on disk."""

from __future__ import annotations

import uuid
from pathlib import Path

import httpx
import pytest
from sqlalchemy import create_engine, text

from learner.checkpoint import read_checkpoint
from tests.server.live import LiveServer
from tests.server.scale import session_body, wait_for_status

pytestmark = pytest.mark.slow


def _rows(server: LiveServer, session_id: int) -> dict[str, int]:
    engine = create_engine(server.database_url)
    with engine.connect() as c:
        counts = {
            table: int(
                c.execute(
                    text(f"SELECT count(*) FROM {table} WHERE session_id = :s"), {"s": session_id}
                ).scalar_one()
            )
            for table in ("steps", "episodes", "advice")
        }
    engine.dispose()
    return counts


def _participants(server: LiveServer, pseudonym: str) -> int:
    engine = create_engine(server.database_url)
    with engine.connect() as c:
        found = c.execute(
            text("SELECT count(*) FROM participants WHERE pseudonym = :p"), {"p": pseudonym}
        ).scalar_one()
    engine.dispose()
    return int(found)


def _finished(api: httpx.Client, study: int, method: str = "oracle", **extra: object) -> dict:
    body = session_body(method, episodes=2, **({"advice_budget": 10} | extra))
    session = api.post(f"/api/studies/{study}/sessions", json=body).json()
    api.post(f"/api/sessions/{session['id']}/start")
    return wait_for_status(api, session["id"], {"finished"})


def _checkpoints(server: LiveServer, session_id: int) -> Path:
    return server.data_dir / "checkpoints" / f"session-{session_id}"


def test_deleting_a_session_removes_its_rows_files_and_the_report(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": f"del-{uuid.uuid4().hex}"}).json()["id"]
    kept = _finished(api, study)
    done = _finished(api, study)  # the newest: SQLite alone would give its id again
    folder = _checkpoints(server, done["id"])
    assert (folder / "final.pt").is_file() and _rows(server, done["id"])["steps"] > 0
    assert api.post(f"/api/studies/{study}/report", json={}).status_code in (200, 201)
    disk = api.get(f"/api/studies/{study}/disk").json()
    assert disk["checkpoint_bytes"] > 0 and disk["report_bytes"] > 0
    assert {s["session_id"] for s in disk["sessions"]} == {done["id"], kept["id"]}

    assert api.delete(f"/api/sessions/{done['id']}").status_code == 204
    assert not folder.exists()
    assert _rows(server, done["id"]) == {"steps": 0, "episodes": 0, "advice": 0}
    assert api.get(f"/api/sessions/{done['id']}").status_code == 404
    assert api.get(f"/api/studies/{study}/report").status_code == 404, "built from its data"
    assert not (server.data_dir / "reports" / f"study-{study}").exists()
    assert (_checkpoints(server, kept["id"]) / "final.pt").is_file(), "others keep theirs"
    assert api.delete(f"/api/sessions/{done['id']}").status_code == 404

    body = session_body("oracle", advice_budget=10)
    newer = api.post(f"/api/studies/{study}/sessions", json=body).json()
    assert newer["id"] > done["id"], "a deleted session's id is never given again"


def test_a_participants_data_is_deleted_with_their_session(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": f"gdpr-{uuid.uuid4().hex}"}).json()["id"]
    pseudonym = f"P-{uuid.uuid4().hex[:8]}"
    body = session_body("human", participant=pseudonym, advice_budget=2)
    created = api.post(f"/api/studies/{study}/sessions", json=body).json()
    assert _participants(server, pseudonym) == 1
    assert api.delete(f"/api/sessions/{created['id']}").status_code == 204
    assert _participants(server, pseudonym) == 0
    with server.client(key=None, token=created["participant_token"]) as gone:
        assert gone.get("/api/participant/state").status_code == 403
        assert gone.get(f"/p/{created['participant_token']}").status_code == 403


def test_a_running_session_and_its_study_cannot_be_deleted(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": f"live-{uuid.uuid4().hex}"}).json()["id"]
    body = session_body("random", advice_budget=10, episodes=500)
    session = api.post(f"/api/studies/{study}/sessions", json=body).json()
    api.post(f"/api/sessions/{session['id']}/start")
    refused = api.delete(f"/api/sessions/{session['id']}")
    assert refused.status_code == 409 and "stop it first" in refused.json()["detail"]
    assert api.delete(f"/api/studies/{study}").status_code == 409
    assert api.post(f"/api/sessions/{session['id']}/stop").json()["status"] == "stopped"
    assert api.delete(f"/api/studies/{study}").status_code == 204
    assert not _checkpoints(server, session["id"]).exists()


def test_a_deleted_studys_files_go_and_its_id_never_returns(
    server: LiveServer, api: httpx.Client
) -> None:
    name = f"gone-{uuid.uuid4().hex}"
    study = api.post("/api/studies", json={"name": name}).json()["id"]
    done = _finished(api, study)
    assert api.post(f"/api/studies/{study}/report", json={}).status_code in (200, 201)
    export = api.get(f"/api/studies/{study}/export")
    assert export.status_code == 200
    assert api.delete(f"/api/studies/{study}").status_code == 204
    assert not _checkpoints(server, done["id"]).exists()
    assert not list((server.data_dir / "reports").glob(f"*study-{study}*"))
    assert not list((server.data_dir / "exports").rglob(f"study-{study}-*"))
    assert _rows(server, done["id"]) == {"steps": 0, "episodes": 0, "advice": 0}

    again = api.post("/api/studies", json={"name": name}).json()["id"]
    assert again > study, "SQLite would hand out the deleted (largest) id again"
    assert api.get(f"/api/studies/{again}/report").status_code == 404
    assert api.get(f"/api/studies/{study}").status_code == 404
    body = session_body("oracle", advice_budget=10)
    fresh = api.post(f"/api/studies/{again}/sessions", json=body).json()
    assert fresh["id"] > done["id"]
    assert not _checkpoints(server, fresh["id"]).exists()


def test_final_checkpoints_leave_the_memory_out_unless_asked(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": f"keep-{uuid.uuid4().hex}"}).json()["id"]
    lean = _finished(api, study)
    kept = _finished(api, study, keep_replay_memory=True)
    lean_state = read_checkpoint(_checkpoints(server, lean["id"]) / "final.pt")
    kept_state = read_checkpoint(_checkpoints(server, kept["id"]) / "final.pt")
    assert lean_state["memory"] is None and kept_state["memory"] is not None
    assert lean["keep_replay_memory"] is None and kept["keep_replay_memory"] is True
    sizes = {
        s["session_id"]: s["checkpoint_bytes"]
        for s in api.get(f"/api/studies/{study}/disk").json()["sessions"]
    }
    assert sizes[lean["id"]] < sizes[kept["id"]]


def test_advisor_checkpoints_are_sessions_of_this_installation_or_files_under_its_data(
    server: LiveServer, api: httpx.Client, tmp_path: Path
) -> None:
    study = api.post("/api/studies", json={"name": f"adv-{uuid.uuid4().hex}"}).json()["id"]
    outside = tmp_path / "outside.pt"
    outside.write_bytes(b"not a checkpoint")
    for spec in ["/etc/passwd", str(outside), "session:999999999", "session:x", "../../etc/hosts"]:
        response = api.post(
            f"/api/studies/{study}/sessions",
            json=session_body("agent", advisor_checkpoint=spec, advice_budget=10),
        )
        assert response.status_code == 422, (spec, response.text)
        assert response.json()["detail"][0]["loc"] == ["body", "run", "advisor_checkpoint"]
    advisor = _finished(api, study, method="autonomous")
    by_session = _finished(
        api, study, method="agent", advisor_checkpoint=f"session:{advisor['id']}"
    )
    final = (_checkpoints(server, advisor["id"]) / "final.pt").resolve()
    assert Path(by_session["run"]["advisor_checkpoint"]) == final
    by_path = api.post(
        f"/api/studies/{study}/sessions",
        json=session_body("agent", advisor_checkpoint=str(final), advice_budget=10),
    )
    assert by_path.status_code == 201, by_path.text
    refused = api.delete(f"/api/sessions/{advisor['id']}")
    assert refused.status_code == 409 and "advises" in refused.json()["detail"]


def test_a_paper_scale_final_checkpoint_is_small_and_still_advises(
    server: LiveServer, api: httpx.Client
) -> None:
    """The paper's network, batch and 20,000-transition memory; few steps, since the
    final checkpoint's size does not depend on how long the run was once the memory is
    left out."""
    study = api.post("/api/studies", json={"name": f"paper-{uuid.uuid4().hex}"}).json()["id"]
    config = {"pretraining_steps": 200, "max_episode_steps": 30, "episodes": 1}
    run = {"method": "autonomous", "seed": 3, "motion": "fast", "config": config}
    advisor = api.post(f"/api/studies/{study}/sessions", json={"run": run}).json()
    api.post(f"/api/sessions/{advisor['id']}/start")
    wait_for_status(api, advisor["id"], {"finished"})
    final = _checkpoints(server, advisor["id"]) / "final.pt"
    size = final.stat().st_size
    state = read_checkpoint(final)
    assert state["config"]["memory_size"] == 20_000 and state["memory"] is None
    print(f"\npaper-scale final checkpoint without the replay memory: {size} bytes")
    assert size < 5_000_000, f"{size} bytes"
    run = {**run, "method": "agent", "advisor_checkpoint": f"session:{advisor['id']}"}
    run["config"] = {**config, "advice_budget": 100}
    agent = api.post(f"/api/studies/{study}/sessions", json={"run": run}).json()
    api.post(f"/api/sessions/{agent['id']}/start")
    trained = wait_for_status(api, agent["id"], {"finished"})
    advice = api.get(f"/api/sessions/{trained['id']}/advice").json()
    assert len(advice) == 100 and {a["advisor"] for a in advice} == {"agent"}
