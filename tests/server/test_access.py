"""Every researcher endpoint needs the key; a participant token reaches one session only."""

from __future__ import annotations

import re
import tempfile

import httpx
import pytest

from server.main import create_app
from study.settings import Settings
from tests.server.live import LiveServer

PUBLIC = {"/api/health"}


def researcher_routes() -> list[tuple[str, str]]:
    """Every (method, path) of the app's schema outside the public and participant ones:
    a new endpoint is checked here without anybody listing it."""
    with tempfile.TemporaryDirectory() as data_dir:
        app = create_app(Settings(api_key="unused", data_dir=data_dir))
        paths = app.openapi()["paths"]
    routes = []
    for template, operations in paths.items():
        if template in PUBLIC or template.startswith("/api/participant"):
            continue
        path = re.sub(r"\{[^}]+\}", "1", template)
        routes += [(method.upper(), path) for method in sorted(operations)]
    assert len(routes) >= 15, routes
    return routes


@pytest.mark.parametrize(("method", "path"), researcher_routes())
def test_researcher_endpoints_refuse_missing_or_wrong_keys(
    server: LiveServer, method: str, path: str
) -> None:
    with server.client(key=None) as anonymous:
        missing = anonymous.request(method, path, json={})
        wrong = anonymous.request(method, path, json={}, headers={"X-API-Key": "wrong"})
    assert missing.status_code == 401, missing.text
    assert "X-API-Key" in missing.json()["detail"]
    assert wrong.status_code == 403, wrong.text


def test_participant_endpoints_refuse_missing_and_forged_tokens(server: LiveServer) -> None:
    with server.client(key=None) as anonymous:
        assert anonymous.get("/api/participant/state").status_code == 401
        forged = server.client(key=None, token="forged-token")
        assert forged.get("/api/participant/state").status_code == 403
        advice = forged.post("/api/participant/advice", json={"advice_index": 0, "action": 1})
        assert advice.status_code == 403
        assert forged.get("/api/participant/observation.png").status_code == 403


def test_the_researcher_key_is_not_a_participant_token(server: LiveServer) -> None:
    with server.client() as researcher:
        response = researcher.get(
            "/api/participant/state",
            headers={"Authorization": f"Bearer {researcher.headers['X-API-Key']}"},
        )
    assert response.status_code == 403


def test_health_needs_no_credentials(server: LiveServer) -> None:
    assert httpx.get(f"{server.url}/api/health").json() == {"status": "ok"}
