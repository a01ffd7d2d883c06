"""Text the databases cannot all store (NUL: PostgreSQL refuses it, SQLite keeps it) and
text that is not Unicode (lone surrogates) get the same 422 on every database: it names the
field and never repeats the input. Runs on PostgreSQL too (DATABASE_URL)."""

from __future__ import annotations

import uuid

import httpx
import pytest

from tests.server.live import LiveServer

SECRET = "s3cret-input"
"""Part of every bad value: a 422 that repeats the input would show it."""
NUL = f'"{SECRET}\\u0000b"'
SURROGATE = f'"{SECRET}\\ud800b"'


def _post(api: httpx.Client, method: str, path: str, body: str) -> httpx.Response:
    return api.request(
        method, path, content=body.encode(), headers={"Content-Type": "application/json"}
    )


def _refused(response: httpx.Response, loc: list[str | int]) -> str:
    assert response.status_code == 422, response.text
    assert SECRET not in response.text, response.text
    [error] = response.json()["detail"]
    assert error["loc"] == loc, error
    return str(error["msg"])


@pytest.fixture
def study(api: httpx.Client) -> int:
    return int(api.post("/api/studies", json={"name": f"text-{uuid.uuid4().hex}"}).json()["id"])


@pytest.mark.parametrize("value", [NUL, SURROGATE], ids=["nul", "surrogate"])
def test_a_study_refuses_text_a_database_cannot_store_naming_the_field(
    api: httpx.Client, study: int, value: str
) -> None:
    name = f'"{uuid.uuid4().hex}"'
    cases = [
        ("POST", "/api/studies", f'{{"name": {value}}}', ["body", "name"]),
        ("POST", "/api/studies", f'{{"name": {name}, "description": {value}}}',
         ["body", "description"]),
        ("POST", "/api/studies", f'{{"name": {name}, "texts": {{"consent": {value}}}}}',
         ["body", "texts", "consent"]),
        ("PATCH", f"/api/studies/{study}", f'{{"description": {value}}}', ["body", "description"]),
        ("PATCH", f"/api/studies/{study}", f'{{"name": {value}}}', ["body", "name"]),
        ("POST", f"/api/studies/{study}/report", f'{{"title": {value}}}', ["body", "title"]),
        ("POST", f"/api/studies/{study}/report", f'{{"label": {value}}}', ["body", "label"]),
    ]  # fmt: skip
    messages = {_refused(_post(api, *case[:3]), case[3]) for case in cases}
    assert len(messages) == 1, messages  # one sentence per kind, whichever field
    [message] = messages
    assert ("NUL" if value == NUL else "surrogate") in message
    names = [s["name"] for s in api.get("/api/studies", params={"limit": 10_000}).json()]
    assert not any(SECRET in n for n in names)


def test_nul_in_a_text_key_is_refused(api: httpx.Client) -> None:
    body = f'{{"name": "{uuid.uuid4().hex}", "texts": {{"x\\u0000": "fine"}}}}'
    response = _post(api, "POST", "/api/studies", body)
    assert response.status_code == 422 and "NUL" in response.json()["detail"][0]["msg"]


def test_text_that_is_fine_is_stored_exactly(api: httpx.Client) -> None:
    name = f"Grüße, 研究 🙂 {uuid.uuid4().hex}"
    created = api.post("/api/studies", json={"name": name, "description": "tab\there\nline"})
    assert created.status_code == 201, created.text
    found = api.get(f"/api/studies/{created.json()['id']}").json()
    assert found["name"] == name and found["description"] == "tab\there\nline"


@pytest.mark.parametrize(
    ("number", "loc"),
    [
        ("9" * 400 + ".5", ["body", "run", "config", "gamma"]),
        ("9" * 5000, ["body", "run", "seed"]),
        ("NaN", ["body", "run", "config", "gamma"]),
    ],
    ids=["400-digit-float", "5000-digit-int", "nan"],
)
def test_a_number_json_cannot_mean_is_a_422_naming_the_field_without_quoting_it(
    api: httpx.Client, study: int, number: str, loc: list[str]
) -> None:
    field = loc[-1]
    body = (
        f'{{"run": {{"method": "oracle", "seed": {number}}}}}'
        if field == "seed"
        else f'{{"run": {{"method": "oracle", "config": {{"gamma": {number}}}}}}}'
    )
    response = _post(api, "POST", f"/api/studies/{study}/sessions", body)
    assert response.status_code == 422, response.text
    assert "9999" not in response.text
    assert response.json()["detail"][0]["loc"] == loc


def test_a_400_digit_integer_or_a_long_text_is_refused_without_quoting_it(
    api: httpx.Client, study: int
) -> None:
    for body in (
        f'{{"run": {{"method": "oracle", "config": {{"loss": "{SECRET}-{"x" * 500}"}}}}}}',
        f'{{"run": {{"method": "oracle", "config": {{"gamma": "{SECRET}"}}}}}}',
        f'{{"run": {{"method": "oracle", "config": {{"batch_size": {"9" * 400}}}}}}}',
        f'{{"run": {{"method": "oracle", "config": {{"episodes": {"9" * 400}}}}}}}',
        f'{{"method": "oracle", "episodes": {"9" * 400}}}',
        f'{{"n_episodes": {"9" * 400}}}',
    ):
        path = "report" if "n_episodes" in body else "sessions"
        response = _post(api, "POST", f"/api/studies/{study}/{path}", body)
        assert response.status_code == 422, response.text
        assert "9999" not in response.text and SECRET not in response.text, response.text


def test_the_dashboard_refuses_nul_in_a_new_study(server: LiveServer) -> None:
    with httpx.Client(base_url=server.url, timeout=60) as browser:
        login = browser.post("/dashboard/login", data={"key": "test-researcher-key"})
        assert login.status_code in (200, 303)
        headers = {"X-Requested-With": "fetch", "Content-Type": "application/json"}
        body = f'{{"name": {NUL}}}'.encode()
        response = browser.post("/dashboard/api/studies", content=body, headers=headers)
        assert response.status_code == 422, response.text
        assert SECRET not in response.text


@pytest.mark.parametrize("value", [NUL, SURROGATE], ids=["nul", "surrogate"])
def test_a_session_refuses_text_a_database_cannot_store_naming_the_field(
    api: httpx.Client, study: int, value: str
) -> None:
    cases = [
        (f'{{"run": {{}}, "label": {value}}}', ["body", "label"]),
        (f'{{"run": {{"method": "human"}}, "participant": {value}}}', ["body", "participant"]),
        (f'{{"run": {{"sort_rule": {value}}}}}', ["body", "run", "sort_rule"]),
        (f'{{"run": {{"method": "agent", "advisor_checkpoint": {value}}}}}',
         ["body", "run", "advisor_checkpoint"]),
    ]  # fmt: skip
    for body, loc in cases:
        message = _refused(_post(api, "POST", f"/api/studies/{study}/sessions", body), loc)
        assert ("NUL" if value == NUL else "surrogate") in message, message
    assert api.get(f"/api/studies/{study}/sessions").json() == []
