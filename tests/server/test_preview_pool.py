"""The researcher's Preview meets what an arrival meets: it takes a practised session from
its condition's pool, as the study link's arrivals do (the pool is topped up again); with
no pooled session it practises from when it is made, not from when its link is opened."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.server.live import LiveServer, serving
from tests.server.test_online_study import TINY_RUN, sessions_of
from tests.server.test_pools import ready, wait_for

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def pooled_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    data_dir = tmp_path_factory.mktemp("preview-pools")
    with serving(data_dir, heartbeat_s=1, pool_limit=1, pool_every_s=0.5) as live:
        yield live


def _design(pool: int) -> dict[str, Any]:
    return {
        "conditions": {"only": {"run": {**TINY_RUN, "seed": 50}, "target": 4}},
        "pool": pool,
        "panel": {"kind": "prolific"},
    }


def test_a_preview_takes_a_practised_session_from_the_pool(pooled_server: LiveServer) -> None:
    server = pooled_server
    with server.client() as api:
        made = api.post("/api/studies", json={"name": "preview", "design": _design(pool=1)})
        assert made.status_code == 201, made.text
        study = made.json()

        def practised() -> list[dict[str, Any]]:
            pooled = [s for s in sessions_of(api, study) if s["pooled"]]
            return [s for s in pooled if s["status"] == "running" and ready(server, s)]

        [kept] = wait_for("a practised session in the pool", practised)
        shown = api.post(f"/api/studies/{study['id']}/preview")
        assert shown.status_code == 201, shown.text
        assert shown.json()["session_id"] == kept["id"], "the pool's practised session"
        previewed = api.get(f"/api/sessions/{kept['id']}").json()
        assert previewed["preview"] and not previewed["pooled"]
        wait_for("the pool topped up", lambda: [s for s in sessions_of(api, study) if s["pooled"]])
        assert api.delete(f"/api/studies/{study['id']}/preview").status_code == 204
        assert api.delete(f"/api/studies/{study['id']}").status_code == 204


def test_a_preview_without_a_pool_practises_from_when_it_is_made(
    pooled_server: LiveServer,
) -> None:
    with pooled_server.client() as api:
        made = api.post("/api/studies", json={"name": "preview, no pool", "design": _design(0)})
        assert made.status_code == 201, made.text
        study = made.json()
        shown = api.post(f"/api/studies/{study['id']}/preview")
        assert shown.status_code == 201, shown.text
        session = shown.json()["session_id"]
        wait_for(
            "its practice started, its link unopened",
            lambda: api.get(f"/api/sessions/{session}").json()["status"] == "running",
            timeout=60,
        )
        assert api.delete(f"/api/studies/{study['id']}/preview").status_code == 204
        assert api.delete(f"/api/studies/{study['id']}").status_code == 204
