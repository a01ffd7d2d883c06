"""The OpenAPI document carries the rules the server enforces on a text, so a client made
from it sends no body the server refuses: every study name and participant pseudonym that
schemathesis draws from the document as valid is accepted (its check
`positive_data_acceptance`, ST202). A NUL is refused in one kind of 422 whichever text holds
it. Runs on PostgreSQL too (DATABASE_URL)."""

from __future__ import annotations

import uuid
from typing import Any

import httpx
import pytest

from tests.server.live import LiveServer

schemathesis = pytest.importorskip("schemathesis")
from hypothesis import HealthCheck, Phase, given, settings  # noqa: E402
from schemathesis.generation.modes import GenerationMode  # noqa: E402

pytestmark = pytest.mark.slow
EXAMPLES = 150
ACCEPTED = {200, 201, 409}
"""A valid body is taken, or (a name already used) a conflict: never a 4xx that says the
body is wrong."""


def _drawn(server: LiveServer, path: str, method: str) -> Any:
    """Valid bodies of an operation, as schemathesis draws them from the served document."""
    schema = schemathesis.openapi.from_url(f"{server.url}/openapi.json")
    return schema[path][method].as_strategy(generation_mode=GenerationMode.POSITIVE)


def _run(strategy: Any, send: Any) -> list[str]:
    refused: list[str] = []

    @given(case=strategy)
    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        database=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    def run(case: Any) -> None:
        sent, response = send(case.body)
        if response.status_code not in ACCEPTED:
            refused.append(f"{sent!r} -> {response.status_code} {response.text[:200]}")

    run()
    return refused


def test_every_study_name_the_document_allows_is_accepted(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": f"rules-{uuid.uuid4().hex}"}).json()["id"]

    def create(body: dict[str, Any]) -> tuple[Any, httpx.Response]:
        drawn = {"name": body["name"], "texts": body.get("texts", {})}  # texts: keys, values
        return drawn, api.post("/api/studies", json=drawn)

    def rename(body: dict[str, Any]) -> tuple[Any, httpx.Response]:
        name = body.get("name")
        return name, api.patch(f"/api/studies/{study}", json={"name": name})

    refused = _run(_drawn(server, "/api/studies", "POST"), create)
    refused += _run(_drawn(server, "/api/studies/{study_id}", "PATCH"), rename)
    assert not refused, "\n".join(refused[:10])
    blank = api.post("/api/studies", json={"name": " \u3000\t"})
    assert blank.status_code == 422, "a blank name is still refused"


def test_every_pseudonym_the_document_allows_is_accepted(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": f"rules-{uuid.uuid4().hex}"}).json()["id"]
    path = f"/api/studies/{study}/sessions"

    def create(body: dict[str, Any]) -> tuple[Any, httpx.Response]:
        participant = body.get("participant")
        session = {"run": {"method": "human"}, "participant": participant}
        return participant, api.post(path, params={"pretrain": "false"}, json=session)

    refused = _run(_drawn(server, "/api/studies/{study_id}/sessions", "POST"), create)
    assert not refused, "\n".join(refused[:10])
    for bad in ("P 01", "P01\n", "é"):
        session = {"run": {"method": "human"}, "participant": bad}
        response = api.post(path, params={"pretrain": "false"}, json=session)
        assert response.status_code == 422, f"{bad!r} is still refused"


def test_the_document_offers_a_run_group_only_as_an_object(api: httpx.Client) -> None:
    """The server takes `config`, `scenario`, `strategy_options` as objects (or left out)."""
    schemas = api.get("/openapi.json").json()["components"]["schemas"]
    for group in ("config", "scenario", "strategy_options"):
        assert "null" not in str(schemas["Run"]["properties"][group]), group
    study = api.post("/api/studies", json={"name": f"rules-{uuid.uuid4().hex}"}).json()["id"]
    refused = api.post(f"/api/studies/{study}/sessions", json={"run": {"config": None}})
    assert refused.status_code == 422, refused.text


def test_a_null_run_version_is_the_current_version(api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": f"rules-{uuid.uuid4().hex}"}).json()["id"]
    body = {"run": {"method": "oracle", "version": None}}
    created = api.post(f"/api/studies/{study}/sessions", json=body)
    assert created.status_code == 201, created.text


def test_nul_is_refused_in_one_kind_of_422_whichever_text_holds_it(api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": f"nul-{uuid.uuid4().hex}"}).json()["id"]
    bodies = [
        ("/api/studies", {"name": "a\x00b"}),
        ("/api/studies", {"name": "fine", "description": "a\x00b"}),
        (f"/api/studies/{study}/sessions", {"run": {}, "label": "a\x00b"}),
        (f"/api/studies/{study}/sessions", {"run": {"sort_rule": "a\x00b"}}),
        (f"/api/studies/{study}/sessions", {"run": {"method": "human"}, "participant": "a\x00"}),
    ]
    kinds = set()
    for path, body in bodies:
        response = api.post(path, json=body, params={"pretrain": "false"})
        assert response.status_code == 422, response.text
        [error] = response.json()["detail"]
        kinds.add((error["type"], error["msg"]))
    assert len(kinds) == 1, kinds
