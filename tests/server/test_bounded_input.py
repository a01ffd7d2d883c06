"""Input from the open internet: bodies are bounded before they are read, credentials are
checked before bodies, and JSON that Python accepts but JSON does not (NaN, Infinity,
lone surrogates) or a bool where a number belongs gets a 422, never a 500."""

from __future__ import annotations

import csv
import io
import socket
import uuid
from pathlib import Path

import httpx
import pandas as pd
import pytest

from analysis.csvsafe import safe_frame
from tests.server.live import API_KEY, LiveServer
from tests.server.scale import export

MiB = 1 << 20


def _rss_kib(pid: int, field: str = "VmRSS") -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise AssertionError(field)


def _flood(port: int, path: str, total: int, chunked: bool, headers: str = "") -> bytes:
    """Send `total` bytes of body (as fast as the server takes them); return its answer."""
    head = f"POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n{headers}"
    head += "Transfer-Encoding: chunked\r\n\r\n" if chunked else f"Content-Length: {total}\r\n\r\n"
    chunk = b"[" + b"1," * (MiB // 2 - 1) + b"1"
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s:
        s.sendall(head.encode())
        sent = 0
        try:
            while sent < total:
                s.sendall(f"{len(chunk):x}\r\n".encode() + chunk + b"\r\n" if chunked else chunk)
                sent += len(chunk)
        except (BrokenPipeError, ConnectionResetError):
            pass  # the server answered and closed: what we want
        answer = b""
        try:
            while b"\r\n\r\n" not in answer:
                data = s.recv(65536)
                if not data:
                    break
                answer += data
        except (ConnectionResetError, TimeoutError):
            pass
    return answer


@pytest.fixture(scope="module")
def participant_token(server: LiveServer) -> tuple[int, str]:
    with server.client() as api:
        study = api.post("/api/studies", json={"name": f"nan-{uuid.uuid4().hex}"}).json()["id"]
        created = api.post(
            f"/api/studies/{study}/sessions", json={"run": {"method": "human"}}
        ).json()
        return study, created["participant_token"]


@pytest.mark.parametrize("credentials", [False, True], ids=["anonymous", "with-credentials"])
@pytest.mark.parametrize("chunked", [False, True], ids=["content-length", "chunked"])
@pytest.mark.parametrize("path", ["/api/participant/advice", "/api/studies"])
def test_an_oversized_body_is_refused_and_memory_stays_bounded(
    server: LiveServer,
    participant_token: tuple[int, str],
    path: str,
    chunked: bool,
    credentials: bool,
) -> None:
    """A declared size over the limit: 413 at once. A chunked body: 401 before a byte is
    read without credentials, 413 as soon as the count passes the limit with them."""
    assert server.process is not None
    pid = server.process.pid
    headers = ""
    if credentials:
        participant = path.startswith("/api/participant")
        headers = (
            f"Authorization: Bearer {participant_token[1]}\r\n"
            if participant
            else f"X-API-Key: {API_KEY}\r\n"
        )
    before = _rss_kib(pid)
    answer = _flood(server.port, path, 300 * MiB, chunked, headers)
    expected = b"HTTP/1.1 413" if credentials or not chunked else b"HTTP/1.1 401"
    assert answer.startswith(expected), answer[:300]
    if expected.endswith(b"413"):
        assert b"larger than this server accepts" in answer
    grown_mib = (_rss_kib(pid) - before) / 1024
    print(f"\n{path} chunked={chunked} credentials={credentials}: RSS {grown_mib:+.1f} MiB")
    assert grown_mib < 40, f"the server grew by {grown_mib:.0f} MiB reading a refused body"
    with server.client() as api:
        big = api.post("/api/studies", content=b'{"name": "' + b"x" * (2 * MiB) + b'"}')
        assert big.status_code == 413, big.text
        ok = api.post("/api/studies", json={"name": f"bounded-{uuid.uuid4().hex}"})
        assert ok.status_code == 201


def test_credentials_are_checked_before_the_body(server: LiveServer) -> None:
    with server.client(key=None) as anonymous:
        for body in [b"{not json", b'{"name": NaN}', b"[" * 100_000]:
            response = anonymous.post(
                "/api/studies", content=body, headers={"Content-Type": "application/json"}
            )
            assert response.status_code == 401, response.text
        forged = anonymous.post(
            "/api/participant/advice",
            content=b'{"advice_index": 0, "action": NaN}',
            headers={"Authorization": "Bearer forged", "Content-Type": "application/json"},
        )
        assert forged.status_code == 403, forged.text


UNENCODABLE = ["NaN", "Infinity", "-Infinity", "1e400", '"\\ud800"', '"a\\udfffb"']


def _post_raw(client: httpx.Client, path: str, body: str) -> httpx.Response:
    return client.post(path, content=body.encode(), headers={"Content-Type": "application/json"})


@pytest.mark.parametrize("value", UNENCODABLE)
def test_nan_infinity_and_surrogates_are_422_for_participants(
    server: LiveServer, participant_token: tuple[int, str], value: str
) -> None:
    _, token = participant_token
    with server.client(key=None, token=token) as participant:
        for body in [
            f'{{"advice_index": 0, "action": {value}}}',
            f'{{"advice_index": {value}, "action": 0}}',
            f'{{"advice_index": 0, "action": 0, "extra": {value}}}',
        ]:
            response = _post_raw(participant, "/api/participant/advice", body)
            assert response.status_code == 422, (body, response.text)
            assert response.json()["detail"][0]["msg"]


@pytest.mark.parametrize("value", UNENCODABLE)
def test_nan_infinity_and_surrogates_are_422_for_researchers(
    server: LiveServer, participant_token: tuple[int, str], value: str
) -> None:
    study, _ = participant_token
    bodies = {
        "/api/studies": [
            f'{{"name": {value}}}',
            f'{{"name": "n", "texts": {{"consent": {value}}}}}',
        ],
        f"/api/studies/{study}/sessions": [
            f'{{"run": {{"method": "oracle", "config": {{"learning_rate": {value}}}}}}}',
            f'{{"run": {{"config": {{{value if value.startswith(chr(34)) else 1}: 1}}}}}}',
            f'{{"run": {{"method": "human"}}, "idle_limit_s": {value}}}',
            f'{{"run": {{"method": "oracle"}}, "label": {value}}}',
        ],
        f"/api/studies/{study}/report": [f'{{"label": {value}}}', f'{{"title": {value}}}'],
    }
    with server.client() as api:
        for path, cases in bodies.items():
            for body in cases:
                response = _post_raw(api, path, body)
                assert response.status_code == 422, (path, body, response.text)
        response = api.patch(
            f"/api/studies/{study}",
            content=f'{{"description": {value}}}'.encode(),
            headers={"Content-Type": "application/json"},
        )
        assert response.status_code == 422, response.text


def test_dashboard_forms_refuse_unencodable_text(server: LiveServer) -> None:
    with httpx.Client(base_url=server.url, timeout=60) as browser:
        login = browser.post("/dashboard/login", data={"key": "test-researcher-key"})
        assert login.status_code in (200, 303)
        headers = {"X-Requested-With": "fetch", "Content-Type": "application/json"}
        for body in ['{"name": "\\ud800"}', '{"name": NaN}']:
            response = browser.post("/dashboard/api/studies", content=body, headers=headers)
            assert response.status_code == 422, response.text
        login = browser.post(
            "/dashboard/login",
            content=b"key=%ED%A0%80",
            headers={"Content-Type": "application/x-www-form-urlencoded"},
        )
        assert login.status_code == 401


def test_numbers_are_strict(server: LiveServer, participant_token: tuple[int, str]) -> None:
    study, token = participant_token
    with server.client() as api:
        for body in [
            {"run": {"method": "human"}, "idle_limit_s": True},
            {"run": {"method": "oracle", "seed": True}},
            {"run": {"method": "oracle", "seed": 1.5}},
            {"run": {"method": "oracle", "config": {"episodes": "5"}}},
            {"run": {"method": "oracle", "error_rate": False}},
            {"run": {"method": "oracle", "config": {"learning_rate": True}}},
        ]:
            response = api.post(f"/api/studies/{study}/sessions", json=body)
            assert response.status_code == 422, (body, response.text)
        fine = api.post(
            f"/api/studies/{study}/sessions", json={"run": {"method": "human"}, "idle_limit_s": 5}
        )
        assert fine.status_code == 201, fine.text
    with server.client(key=None, token=token) as participant:
        response = participant.post(
            "/api/participant/advice", json={"advice_index": 0, "action": True}
        )
        assert response.status_code == 422


@pytest.mark.parametrize("body", [b"\xc2", b'{"name": "\xff\xfe"}', b"\x92\x8f\xca'"])
def test_a_body_that_is_not_utf8_is_422(server: LiveServer, body: bytes) -> None:
    with server.client() as api:
        response = api.post(
            "/api/studies", content=body, headers={"Content-Type": "application/json"}
        )
    assert response.status_code == 422, response.text
    assert "UTF-8" in response.json()["detail"][0]["msg"]


def test_a_422_names_the_field_without_echoing_what_was_sent(
    server: LiveServer, participant_token: tuple[int, str]
) -> None:
    study, _ = participant_token
    sent = "echo-me-" + "x" * 40
    with server.client() as api:
        for body in [
            {"run": {"method": sent}},
            {"run": {"method": "oracle", "seed": sent}},
            {"run": {"method": "oracle", "scenario": {"reward_scheme": sent}}},
            {"run": {"method": "oracle", "sort_rule": sent}},
            {"run": {"method": "oracle", "config": {sent: 1}}},
            {"run": {"method": "agent", "advisor_checkpoint": sent}},
            {"method": sent},
        ]:
            response = api.post(f"/api/studies/{study}/sessions", json=body)
            assert response.status_code == 422, response.text
            assert sent not in response.text and '"input"' not in response.text
            assert response.json()["detail"][0]["loc"][0] == "body"


def test_a_422_names_an_unknown_field_and_says_where_a_runs_field_belongs(
    server: LiveServer, participant_token: tuple[int, str]
) -> None:
    """A field name that is a plain identifier is named (it is what the sender must fix);
    one that a run has elsewhere says where, and any other says which fields the object
    has, wherever it is: beside `run`, in it, in its groups, in a study's design. Other
    names the sender wrote are not echoed."""
    study, _ = participant_token
    long_name = "echo_me_" + "x" * 60
    cases: list[tuple[str, dict[str, object], list[str], str]] = [
        ("sessions", {"run": {"method": "oracle", "advice_budget": 5}},
         ["body", "run", "advice_budget"], " here: it belongs in run.config.advice_budget"),
        ("sessions", {"advice_budget": 5, "run": {"method": "oracle"}},
         ["body", "advice_budget"], " here: it belongs in run.config.advice_budget"),
        ("sessions", {"run": {"method": "oracle", "config": {"reward_scheme": "paper"}}},
         ["body", "run", "config", "reward_scheme"],
         " here: it belongs in run.scenario.reward_scheme"),
        ("sessions", {"colour": 1, "run": {"method": "oracle"}},
         ["body", "colour"], "; valid fields: label, participant, keep_replay_memory, "),
        ("sessions", {"run": {"method": "oracle", "colour": 1}},
         ["body", "run", "colour"], "; valid fields: method, seed, preset, config, "),
        ("sessions", {"run": {"method": "oracle", "config": {"colour": 1}}},
         ["body", "run", "config", "colour"], "; valid fields: episodes, max_episode_steps, "),
        ("sessions", {"run": {"method": "oracle", "scenario": {"colour": 1}}},
         ["body", "run", "scenario", "colour"],
         "; valid fields: reward_scheme, grasp_failure_rate, knock_off_rate"),
        ("studies", {"name": f"unknown-{uuid.uuid4().hex}", "seed": 3},
         ["body", "seed"], "; valid fields: description, texts, name, design"),  # no run here
        ("studies", {"name": f"unknown-{uuid.uuid4().hex}", "design": {
            "conditions": {"a": {"run": {"method": "human"}}}, "colour": 1}},
         ["body", "design", "colour"], "; valid fields: conditions, capacity, alpha, "),
    ]  # fmt: skip
    with server.client() as api:
        for endpoint, body, loc, hint in cases:
            path = f"/api/studies/{study}/sessions" if endpoint == "sessions" else "/api/studies"
            response = api.post(path, json=body)
            assert response.status_code == 422, response.text
            error = response.json()["detail"][0]
            assert error["loc"] == loc and f"unknown field '{loc[-1]}'{hint}" in error["msg"]
            assert "openapi.json" not in error["msg"], error
        response = api.post(
            f"/api/studies/{study}/sessions", json={"run": {"method": "oracle", long_name: 1}}
        )
    assert response.status_code == 422, response.text
    assert long_name not in response.text
    (error,) = response.json()["detail"]
    assert error["loc"][-1] == "(unknown field)"
    assert error["msg"].startswith("an unknown field; valid fields: method, seed, "), error


def test_a_422_reads_as_a_person_would_and_hides_only_the_value_it_is_about(
    server: LiveServer, participant_token: tuple[int, str]
) -> None:
    study, token = participant_token
    with server.client(key=None, token=token) as participant:  # a union: int, float or text
        wrong = participant.post(
            "/api/participant/questionnaire", json={"answers": {"trust": {"q1": [1]}}}
        )
    assert wrong.status_code == 422, wrong.text
    steps = [part for item in wrong.json()["detail"] for part in item["loc"]]
    assert " at 0x" not in wrong.text and "function-after" not in wrong.text, wrong.text
    assert {"int", "float", "str"} <= set(steps), steps
    with server.client() as api:  # the message's list of allowed schemes, one of them sent
        body = {
            "label": "authors-interactive",
            "run": {"method": "oracle", "scenario": {"reward_scheme": "a-scheme-of-mine"}},
        }
        response = api.post(f"/api/studies/{study}/sessions", json=body)
    assert response.status_code == 422, response.text
    assert "a-scheme-of-mine" not in response.text and "authors-interactive" in response.text


def test_every_text_field_is_bounded(
    server: LiveServer, participant_token: tuple[int, str]
) -> None:
    study, _ = participant_token
    with server.client() as api:
        name = f"texts-{uuid.uuid4().hex}"
        for body in [
            {"name": name, "texts": {"consent": "x" * 60_000}},
            {"name": name, "texts": {f"k{i}": "x" for i in range(40)}},
            {"name": name, "texts": {"k" * 100: "x"}},
        ]:
            response = api.post("/api/studies", json=body)
            assert response.status_code == 422, response.text[:300]
        response = api.patch(f"/api/studies/{study}", json={"texts": {"consent": "y" * 60_000}})
        assert response.status_code == 422
        for body in [
            {"run": {"method": "oracle", "preset": "p" * 100}},
            {"run": {"method": "oracle", "sort_rule": "c" * 500}},
            {"run": {"method": "oracle", "config": {f"f{i}": 1 for i in range(200)}}},
            {"run": {"method": "agent", "advisor_checkpoint": "/" + "a" * 5000}},
            {"run": {}, "label": "l" * 300},
        ]:
            response = api.post(f"/api/studies/{study}/sessions", json=body)
            assert response.status_code == 422, response.text[:300]
        response = api.post(f"/api/studies/{study}/report", json={"methods": ["m" * 100]})
        assert response.status_code == 422


def test_security_headers_on_every_page(
    server: LiveServer, participant_token: tuple[int, str]
) -> None:
    _, token = participant_token
    with httpx.Client(base_url=server.url, timeout=60) as browser:
        for path in ["/dashboard/login", f"/p/{token}/consent", "/api/health", "/p/forged"]:
            response = browser.get(path)
            assert response.headers["x-content-type-options"] == "nosniff", path
            assert response.headers["x-frame-options"] == "SAMEORIGIN", path
            policy = response.headers["content-security-policy"]
            assert "frame-ancestors 'self'" in policy and "script-src 'self';" in policy, path
        docs = browser.get("/docs")
        policy = docs.headers["content-security-policy"]
        assert "script-src 'self' 'unsafe-inline';" in policy and "https:" not in policy
        for guess in ("/api/docs", "/redoc"):  # where people look for the docs
            moved = browser.get(guess)
            assert moved.status_code == 307 and moved.headers["location"] == "/docs", guess


FORMULAS = ['=HYPERLINK("http://evil.example","click")', "+cmd|' /C calc'!A0", "@SUM(A1)", "-2+3"]


def test_spreadsheet_formulas_are_neutralised_in_every_export_cell(
    server: LiveServer,
) -> None:
    with server.client() as api:
        study = api.post("/api/studies", json={"name": f"=csv-{uuid.uuid4().hex}"}).json()["id"]
        for label in FORMULAS:
            body = {"run": {"method": "human"}, "label": label, "participant": "P1"}
            assert api.post(f"/api/studies/{study}/sessions", json=body).status_code == 201
        files = export(api, study)
    rows = list(csv.DictReader(io.StringIO(files["sessions.csv"].decode())))
    assert [r["label"] for r in rows] == ["'" + f for f in FORMULAS]
    for name, data in files.items():
        if name.endswith(".csv"):
            for row in csv.reader(io.StringIO(data.decode())):
                assert not any(cell.startswith(("=", "+", "@")) for cell in row), (name, row)
    assert rows[0]["seed"] == "0", "numbers are left alone"


def test_report_tables_are_neutralised_too() -> None:
    frame = pd.DataFrame({"=agent": ["=1+1", "ok"], "reward": [-1.5, 2.0]}, index=["@a", "b"])
    safe = safe_frame(frame)
    assert list(safe.columns) == ["'=agent", "reward"] and list(safe.index) == ["'@a", "b"]
    assert safe["'=agent"].tolist() == ["'=1+1", "ok"] and safe["reward"].tolist() == [-1.5, 2.0]
