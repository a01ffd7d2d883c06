"""A participant's state is read from the database off the event loop when their session
has no live worker (finished, queued on the database, or never started), so many pages
polling never stall the server's other requests."""

from __future__ import annotations

import asyncio
from pathlib import Path

from fastapi.testclient import TestClient

from server.main import create_app
from study.settings import Settings
from tests.server.live import API_KEY, fresh_database


def test_state_of_a_session_without_a_worker_is_read_off_the_event_loop(tmp_path: Path) -> None:
    with fresh_database(tmp_path) as url:
        settings = Settings(data_dir=tmp_path / "data", database_url=url, api_key=API_KEY)
        app = create_app(settings)
        on_loop: list[bool] = []
        manager = app.state.manager
        factory = manager.factory

        def watched() -> object:
            try:
                asyncio.get_running_loop()
                on_loop.append(True)
            except RuntimeError:
                on_loop.append(False)
            return factory()

        with TestClient(app) as client:
            headers = {"X-API-Key": API_KEY}
            study = client.post("/api/studies", json={"name": "polling"}, headers=headers)
            made = client.post(
                f"/api/studies/{study.json()['id']}/sessions",
                json={"run": {"method": "human"}},
                headers=headers,
            ).json()
            manager.factory = watched
            bearer = {"Authorization": f"Bearer {made['participant_token']}"}
            for _ in range(3):
                state = client.get("/api/participant/state", headers=bearer)
                assert state.status_code == 200, state.text
                assert state.json()["status"] == "created"
        assert on_loop and not any(on_loop), on_loop
