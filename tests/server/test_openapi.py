"""The OpenAPI contract, as clients nobody here wrote read it: a validator, a client
generated from /openapi.json, and every operation probed for the statuses it declares."""

from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.server.live import API_KEY, LiveServer

PROBE_ID = 987654


@pytest.fixture(scope="module")
def spec(server: LiveServer) -> dict[str, Any]:
    with server.client() as client:
        return client.get("/openapi.json").json()


def operations(spec: dict[str, Any]) -> list[tuple[str, str, dict[str, Any]]]:
    return [
        (path, method, operation)
        for path, methods in spec["paths"].items()
        for method, operation in methods.items()
    ]


def test_the_document_is_valid_openapi(spec: dict[str, Any]) -> None:
    validator = pytest.importorskip("openapi_spec_validator")
    validator.validate(spec)


def test_operation_ids_are_the_route_names(spec: dict[str, Any]) -> None:
    ids = [operation["operationId"] for _, _, operation in operations(spec)]
    assert len(ids) == len(set(ids))
    assert all(re.fullmatch(r"[a-z][a-z_]*[a-z]", i) for i in ids), ids
    assert {"create_study", "get_study", "start_session", "participant_give_advice"} <= set(ids)


def test_every_error_uses_the_one_error_model_and_downloads_are_binary(
    spec: dict[str, Any],
) -> None:
    for path, _, operation in operations(spec):
        for code, response in operation["responses"].items():
            if code.startswith(("4", "5")):
                schema = response["content"]["application/json"]["schema"]
                assert schema == {"$ref": "#/components/schemas/ErrorBody"}, (path, code)
        for media, content in operation["responses"].get("200", {}).get("content", {}).items():
            if media != "application/json":
                assert content["schema"] == {"type": "string", "format": "binary"}, path
    assert "HTTPValidationError" not in spec["components"]["schemas"]
    png = spec["paths"]["/api/sessions/{session_id}/advice/{advice_index}.png"]["get"]
    assert "image/png" in png["responses"]["200"]["content"]


def _call(client: httpx.Client, path: str, method: str, operation: dict[str, Any]) -> int:
    url = re.sub(r"\{[^}]+\}", str(PROBE_ID), path)
    body = {} if "requestBody" in operation else None
    return client.request(method, url, json=body).status_code


def test_every_operation_returns_only_statuses_it_declares(
    server: LiveServer, spec: dict[str, Any]
) -> None:
    """No key, a wrong key, a wrong participant token, and ids that name nothing."""
    seen: set[int] = set()
    clients = {
        "none": server.client(key=None),
        "wrong key": server.client(key="not-the-key"),
        "wrong token": server.client(key=None, token="not-a-token"),
        "researcher": server.client(),
    }
    try:
        for path, method, operation in operations(spec):
            declared = {int(code) for code in operation["responses"]}
            for who, client in clients.items():
                status = _call(client, path, method, operation)
                seen.add(status)
                assert status in declared, f"{method.upper()} {path} as {who}: {status}"
    finally:
        for client in clients.values():
            client.close()
    assert {401, 403, 404, 422} <= seen


def test_a_body_too_large_is_a_declared_413_on_every_route_that_reads_one(
    server: LiveServer, spec: dict[str, Any]
) -> None:
    """The guard refuses any POST, PUT, PATCH or DELETE over the size limit (1 MiB by
    default) before the route sees it: each such operation declares it, the others not."""
    too_large = b"{" + b" " * 1_048_576 + b"}"
    bodies = 0
    with server.client() as client:
        for path, method, operation in operations(spec):
            declared = {int(code) for code in operation["responses"]}
            if method.upper() not in {"POST", "PUT", "PATCH", "DELETE"}:
                assert 413 not in declared, f"{method.upper()} {path}"
                continue
            assert 413 in declared, f"{method.upper()} {path}"
            bodies += "requestBody" in operation
            url = re.sub(r"\{[^}]+\}", str(PROBE_ID), path)
            response = client.request(
                method, url, content=too_large, headers={"Content-Type": "application/json"}
            )
            assert response.status_code == 413, f"{method.upper()} {path}: {response.text}"
            assert "IDEEPRL_MAX_REQUEST_BYTES" in response.json()["detail"]
    assert bodies >= 3  # create_study, create_session, participant_give_advice at least


def test_list_endpoints_page_with_limit_and_offset(api: httpx.Client) -> None:
    ids = [api.post("/api/studies", json={"name": f"paged {i}"}).json()["id"] for i in range(3)]
    everything = [s["id"] for s in api.get("/api/studies").json()]
    assert everything[-3:] == ids
    start = everything.index(ids[0])
    page = api.get("/api/studies", params={"limit": 2, "offset": start}).json()
    assert [s["id"] for s in page] == ids[:2]
    assert api.get("/api/studies", params={"limit": 0}).status_code == 422
    paths = api.get("/openapi.json").json()["paths"]
    for path in (
        "/api/studies/{study_id}/sessions",
        "/api/sessions/{session_id}/episodes",
        "/api/sessions/{session_id}/advice",
    ):
        assert {"limit", "offset"} <= {p["name"] for p in paths[path]["get"]["parameters"]}


@pytest.fixture(scope="module")
def generated_client(spec: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A client package generated by openapi-python-client from the served document."""
    generator = Path(sys.executable).with_name("openapi-python-client")
    if not generator.exists():
        pytest.skip("openapi-python-client is not installed (pip install -e '.[dev]')")
    folder = tmp_path_factory.mktemp("client")
    document = folder / "openapi.json"
    document.write_text(json.dumps(spec))
    env = {**os.environ, "PATH": f"{generator.parent}{os.pathsep}{os.environ['PATH']}"}
    subprocess.run(
        [str(generator), "generate", "--path", str(document), "--meta", "none",
         "--output-path", str(folder / "ideeprl_client")],
        check=True, capture_output=True, env=env, timeout=300,
    )  # fmt: skip
    sys.path.insert(0, str(folder))
    try:
        yield importlib.import_module("ideeprl_client")
    finally:
        sys.path.remove(str(folder))


def test_a_generated_client_creates_a_study_and_a_session_and_gets_typed_errors(
    server: LiveServer, generated_client: Any
) -> None:
    package = generated_client.__name__
    client = generated_client.AuthenticatedClient(
        base_url=server.url,
        token=API_KEY,
        prefix="",
        auth_header_name="X-API-Key",
        raise_on_unexpected_status=True,
    )
    models = importlib.import_module(f"{package}.models")
    create = importlib.import_module(f"{package}.api.studies.create_study")
    created = create.sync_detailed(client=client, body=models.StudyCreate(name="generated"))
    assert created.status_code == 201 and isinstance(created.parsed, models.StudyPublic)
    study = created.parsed
    assert study.name == "generated" and study.created_at.tzinfo is not None

    again = create.sync_detailed(client=client, body=models.StudyCreate(name="generated"))
    assert again.status_code == 409 and isinstance(again.parsed, models.ErrorBody)
    assert "exists already" in again.parsed.detail

    get_study = importlib.import_module(f"{package}.api.studies.get_study")
    missing = get_study.sync_detailed(client=client, study_id=PROBE_ID)
    assert missing.status_code == 404 and isinstance(missing.parsed, models.ErrorBody)
    assert f"no study with id {PROBE_ID}" in missing.parsed.detail

    create_session = importlib.import_module(f"{package}.api.sessions.create_session")
    body = models.SessionCreate.from_dict({"run": {"method": "autonomous", "seed": 3}})
    session = create_session.sync_detailed(client=client, study_id=study.id, body=body)
    assert session.status_code == 201, session.content
    assert session.parsed.study_id == study.id and session.parsed.seed == 3
    get_session = importlib.import_module(f"{package}.api.sessions.get_session")
    assert get_session.sync(client=client, session_id=session.parsed.id).status == "created"
    pause = importlib.import_module(f"{package}.api.sessions.pause_session")
    not_running = pause.sync_detailed(client=client, session_id=session.parsed.id)
    assert not_running.status_code == 409 and isinstance(not_running.parsed, models.ErrorBody)


def _finished_oracle_session(api: httpx.Client) -> tuple[int, int]:
    """(study id, session id) of a small oracle-advised session, run to its end."""
    from tests.server.scale import session_body, wait_for_status

    study = api.post("/api/studies", json={"name": "generated downloads"}).json()["id"]
    body = session_body("oracle", advice_budget=3)
    session = api.post(f"/api/studies/{study}/sessions", json=body).json()["id"]
    assert api.post(f"/api/sessions/{session}/start").status_code == 200
    wait_for_status(api, session, {"finished"})
    return study, session


def test_a_generated_client_downloads_every_file_byte_for_byte(
    server: LiveServer, api: httpx.Client, generated_client: Any
) -> None:
    """Exports (CSV, Parquet), the report's zip and each of its files (Markdown, PNG,
    CSV) and an advice PNG, through a client generated with default settings, equal the
    bytes a plain GET receives."""
    package = generated_client.__name__
    client = generated_client.AuthenticatedClient(
        base_url=server.url,
        token=API_KEY,
        prefix="",
        auth_header_name="X-API-Key",
        raise_on_unexpected_status=True,
    )
    study, session = _finished_oracle_session(api)
    report = api.post(f"/api/studies/{study}/report", json={})
    assert report.status_code == 201, report.text
    files = report.json()["files"]
    assert {f["kind"] for f in files} >= {"figure", "table", "report"}

    def module(name: str) -> Any:
        return importlib.import_module(f"{package}.api.{name}")

    export = module("exports.export_study")
    formats = importlib.import_module(f"{package}.models.export_study_format")
    report_file = module("reports.get_report_file")
    downloads = [
        (export.sync_detailed(client=client, study_id=study), f"/api/studies/{study}/export"),
        (
            export.sync_detailed(
                client=client, study_id=study, format_=formats.ExportStudyFormat.PARQUET
            ),
            f"/api/studies/{study}/export?format=parquet",
        ),
        (
            module("reports.get_report_zip").sync_detailed(client=client, study_id=study),
            f"/api/studies/{study}/report.zip",
        ),
        (
            module("sessions.advice_observation").sync_detailed(
                client=client, session_id=session, advice_index=0
            ),
            f"/api/sessions/{session}/advice/0.png",
        ),
        *[
            (report_file.sync_detailed(client=client, study_id=study, name=f["name"]), f["url"])
            for f in files
        ],
    ]
    for response, url in downloads:
        assert response.status_code == 200, url
        assert response.parsed is not None, f"{url}: the client has no 200 response for it"
        received = response.parsed.payload.read()
        direct = api.get(url)
        assert direct.status_code == 200, url
        if url.endswith((".zip", "export", "parquet")):  # zips carry their time of packing
            assert _zip_entries(received) == _zip_entries(direct.content), url
        else:
            assert received == direct.content, url
    assert {url.rsplit(".", 1)[-1] for _, url in downloads} >= {"png", "md", "csv", "zip"}


def _zip_entries(data: bytes) -> dict[str, bytes]:
    import io
    import zipfile

    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def test_a_405_names_every_method_of_its_path(server: LiveServer, spec: dict[str, Any]) -> None:
    """`Allow` lists what the path takes, not only the first route's method."""
    several = 0
    with server.client() as client:
        for path, methods in spec["paths"].items():
            declared = {m.upper() for m in methods}
            url = re.sub(r"\{[^}]+\}", str(PROBE_ID), path)
            wrong = next(m for m in ("PUT", "PATCH", "DELETE", "POST", "GET") if m not in declared)
            response = client.request(wrong, url)
            assert response.status_code == 405, f"{wrong} {path}: {response.status_code}"
            allowed = {m.strip() for m in response.headers["allow"].split(",")}
            assert declared <= allowed, f"{path}: Allow {allowed}, has {declared}"
            several += len(declared) > 1
    assert several >= 6
