"""A report names the sessions it leaves out for not being finished, and why: one not
finished yet is waited for, or included by the caller's own options (the command line's,
the REST body's; the dashboard names where to choose); one that ended without finishing (a
participant who declined consent, a stopped run) is named so, never suggested."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from cli.main import main
from study.db.engine import make_engine, make_session_factory
from study.db.models import Episode, Status, StudySession
from tests.server.live import API_KEY, LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body

REST = "the body's `sessions` (their ids) and `n_episodes`"
CLI = "`--sessions ID ...` and `--n-episodes N`"


def _set(server: LiveServer, session_id: int, status: Status, episodes: int = 0) -> None:
    """The session's status as its worker would leave it, with its training episodes."""
    engine = make_engine(server.database_url)
    with make_session_factory(engine)() as db:
        session = db.get(StudySession, session_id)
        assert session is not None
        session.status = status.value
        for i in range(1, episodes + 1):
            db.add(
                Episode(
                    session_id=session_id, stage="train", episode=i, collected_reward=float(i),
                    steps=40, placed_correct=1, misplaced=0, lost=0, success=False,
                    terminated=False, truncated=True, advised_steps=0, epsilon=0.5,
                    first_global_step=(i - 1) * 40 + 1, last_global_step=i * 40, wall_time=0.0,
                )
            )  # fmt: skip
        db.commit()
    engine.dispose()


@pytest.mark.slow
def test_sessions_that_ended_are_named_and_never_suggested(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study = api.post("/api/studies", json={"name": "ended or under way"}).json()["id"]

    def make(method: str, **fields: object) -> dict[str, object]:
        made = api.post(f"/api/studies/{study}/sessions", json=session_body(method, **fields))
        assert made.status_code == 201, made.text
        return made.json()

    declined = make("human", participant="P-declined", advice_budget=3)
    SimulatedParticipant(server.url, str(declined["participant_token"])).consent(agree=False)
    visiting = make("human", participant="P-visiting", advice_budget=3)  # has not decided yet
    stopped = make("autonomous", seed=1)
    _set(server, int(stopped["id"]), Status.stopped)
    waiting = (
        f"session {visiting['id']} (not started); wait until it finishes, or include it as it is"
    )
    ended = (
        f"session {declined['id']} (declined consent), session {stopped['id']} (stopped by the "
        "researcher)"
    )

    refused = api.post(f"/api/studies/{study}/report", json={})
    assert refused.status_code == 409, refused.text
    detail = refused.json()["detail"]
    assert detail == (
        f"study {study} has no finished session. Not finished yet: {waiting} with {REST}. "
        f"Ended without finishing: {ended}"
    )
    with httpx.Client(base_url=server.url, timeout=120) as dashboard:
        assert dashboard.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
        built = dashboard.post(
            f"/dashboard/api/studies/{study}/report", headers={"X-Requested-With": "test"}
        )
    assert built.status_code == 409, built.text
    on_the_dashboard = built.json()["detail"]
    assert f"{waiting} with `POST /api/studies/{study}/report` (the body's `sessions` and " in (
        on_the_dashboard
    )
    assert f"`ideeprl report --study {study} --sessions ID ... --n-episodes N`" in on_the_dashboard
    assert on_the_dashboard.endswith(f"Ended without finishing: {ended}")
    flags = ["--study", str(study), "--database-url", server.database_url]
    assert main(["report", *flags, "--out", str(tmp_path / "none")]) == 1
    assert f"Not finished yet: {waiting} with {CLI}. Ended" in capsys.readouterr().err

    # Once sessions finished, the others are left out, each kind with its own note.
    for seed in (2, 3):
        _set(server, int(make("autonomous", seed=seed)["id"]), Status.finished, episodes=3)
    report = api.post(f"/api/studies/{study}/report", json={})
    assert report.status_code == 201, report.text
    notes = report.json()["notes"]
    assert f"Left out 1 session not finished yet: {waiting} with {REST}." in notes
    assert f"Left out 2 sessions that ended without finishing: {ended}." in notes
    suggested = [n for n in notes if "include" in n]
    assert suggested and not any(f"session {declined['id']} (" in n for n in suggested)
    assert main(["report", *flags, "--out", str(tmp_path / "report")]) == 0
    assert f"note: Left out 1 session not finished yet: {waiting} with {CLI}." in (
        capsys.readouterr().out
    )
