"""The OpenAPI document carries the rules the server enforces on a text, so a client made
from it sends no body the server refuses: every study name and participant pseudonym that
schemathesis draws from the document as valid is accepted (its check
`positive_data_acceptance`, ST202). A NUL is refused in one kind of 422 whichever text holds
it. Runs on PostgreSQL too (DATABASE_URL)."""

from __future__ import annotations

import re
import uuid
from collections.abc import Iterator
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
    assert blank.json()["detail"][0]["msg"] == "A name must not be blank"


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
        assert "matching [A-Za-z0-9_-]+" in response.text, "it says what a pseudonym holds"


def _texts(schema: dict[str, Any], where: str, document: dict[str, Any]) -> Iterator[Any]:
    """(where, schema) of every text in `schema`: a string value or a map's key."""
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        if name not in where.split("."):  # a model met again inside itself
            yield from _texts(document["components"]["schemas"][name], name, document)
        return
    for alternative in schema.get("anyOf", []) + schema.get("allOf", []):
        yield from _texts(alternative, where, document)
    chosen = {"enum", "const", "format"} & set(schema)  # a choice, not a free text
    if schema.get("type") == "string" and not chosen:
        yield where, schema
    for name, value in schema.get("properties", {}).items():
        yield from _texts(value, f"{where}.{name}", document)
    if isinstance(schema.get("additionalProperties"), dict):
        yield from _texts(schema["additionalProperties"], f"{where}[value]", document)
    if "propertyNames" in schema:
        yield from _texts({"type": "string", **schema["propertyNames"]}, f"{where}[key]", document)
    if "items" in schema:
        yield from _texts(schema["items"], f"{where}[]", document)


def test_every_text_of_a_body_carries_a_whole_pattern_that_refuses_nul(
    api: httpx.Client,
) -> None:
    """The server reads a text whole (no NUL anywhere; a form such as `shape/color`
    matched in full), while a JSON Schema `pattern` is a search: without one, or with one
    anchored at its start only, a client made from the document sends texts the server
    refuses."""
    document = api.get("/openapi.json").json()
    loose = set()
    for path, operations in document["paths"].items():
        for method, operation in operations.items():
            content = operation.get("requestBody", {}).get("content", {})
            for media in content.values():
                for where, text in _texts(media["schema"], f"{method} {path}", document):
                    pattern = text.get("pattern", "")
                    whole = pattern.startswith("^") and pattern.endswith("$")
                    if not whole or re.search(pattern, "\x00") or re.search(pattern, "a\x00"):
                        loose.add(f"{where}: {pattern or 'no pattern'}")
    assert not loose, "\n".join(sorted(loose))


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


def _designed(**design: Any) -> dict[str, Any]:
    """A study's body with an online design (one condition) holding `design`."""
    return {"name": f"designed-{uuid.uuid4().hex}", "design": {"conditions": {"a": {}}, **design}}


def _side_question(side_of: str) -> dict[str, Any]:
    sides = [{"value": "left", "label": "Left"}, {"value": "right", "label": "Right"}]
    return {"id": "q", "text": "Where does it go?", "choices": sides, "side_of": side_of}


def test_a_check_question_s_object_is_one_the_document_names(api: httpx.Client) -> None:
    question = api.get("/openapi.json").json()["components"]["schemas"]["CheckQuestion"]
    [named, _] = question["properties"]["side_of"]["anyOf"]
    assert re.search(named["pattern"], "disk/blue") and not re.search(named["pattern"], "disk")
    taken = api.post(
        "/api/studies", json=_designed(check={"questions": [_side_question("disk/blue")]})
    )
    assert taken.status_code == 201, taken.text
    refused = api.post(
        "/api/studies", json=_designed(check={"questions": [_side_question("disk")]})
    )
    assert refused.status_code == 422, refused.text
    assert "is not an object shape/color (shapes cube" in refused.text, "it says what to send"


def test_nul_is_refused_in_one_kind_of_422_whichever_text_holds_it(api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": f"nul-{uuid.uuid4().hex}"}).json()["id"]
    bodies = [
        ("/api/studies", {"name": "a\x00b"}),
        ("/api/studies", {"name": "fine", "description": "a\x00b"}),
        (f"/api/studies/{study}/sessions", {"run": {}, "label": "a\x00b"}),
        (f"/api/studies/{study}/sessions", {"run": {"sort_rule": "a\x00b"}}),
        (f"/api/studies/{study}/sessions", {"run": {"method": "human"}, "participant": "a\x00"}),
        ("/api/studies", _designed(panel={"urls": {"completed": "https://a.org/\x00"}})),
        ("/api/studies", _designed(check={"questions": [_side_question("cube/red\x00")]})),
    ]
    kinds = set()
    for path, body in bodies:
        response = api.post(path, json=body, params={"pretrain": "false"})
        assert response.status_code == 422, response.text
        [error] = response.json()["detail"]
        kinds.add((error["type"], error["msg"]))
    assert len(kinds) == 1, kinds
