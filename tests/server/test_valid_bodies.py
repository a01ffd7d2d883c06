"""A body the OpenAPI document allows is accepted, as schemathesis's check
`positive_data_acceptance` (ST202) expects of every operation: a study design's condition
runs are the session body's `Run`, an integer may be written `133.0` (JSON Schema's
`integer`), and a report naming sessions the study lacks is a 404 that says where to find
them. The one kind of refusal left is a rule between a run's fields (`pretraining_steps` at
least `batch_size`, `RunSpec.validate`), which JSON Schema cannot state: a 422 naming the
field and the rule. Runs on PostgreSQL too (DATABASE_URL)."""

from __future__ import annotations

import uuid
from typing import Any

import httpx
import pytest

from learner.fields import FieldError
from learner.run import declared
from study.schemas.runs import given
from study.schemas.sessions import run_model
from tests.server.live import API_KEY, LiveServer

schemathesis = pytest.importorskip("schemathesis")
from hypothesis import HealthCheck, Phase, settings  # noqa: E402
from hypothesis import given as drawn  # noqa: E402
from schemathesis.generation.modes import GenerationMode  # noqa: E402
from schemathesis.specs.openapi.checks import positive_data_acceptance  # noqa: E402

pytestmark = pytest.mark.slow
EXAMPLES = 60


def _study(api: httpx.Client, **body: Any) -> httpx.Response:
    return api.post("/api/studies", json={"name": f"valid-{uuid.uuid4().hex}", **body})


def test_a_condition_run_is_the_session_run_in_the_document(api: httpx.Client) -> None:
    schemas = api.get("/openapi.json").json()["components"]["schemas"]
    run = schemas["Condition"]["properties"]["run"]
    assert {"$ref": "#/components/schemas/Run"} in run["allOf"], run
    assert {"properties": {"method": {"enum": ["human"], "default": "human"}}} in run["allOf"]

    runs = {"a": {}, "b": {"seed": 3, "version": None}, "c": {"config": {"episodes": 2}}}
    created = _study(api, design={"conditions": {k: {"run": v} for k, v in runs.items()}})
    assert created.status_code == 201, created.text
    stored = created.json()["design"]["conditions"]
    assert {name: c["run"]["method"] for name, c in stored.items()} == dict.fromkeys(runs, "human")
    assert stored["b"]["run"]["seed"] == 3 and stored["c"]["run"]["config"]["episodes"] == 2

    for run, where in (
        ({"method": "agent"}, ["method"]),
        ({"config": {"batch_size": "x"}}, ["config", "batch_size"]),
        ({"nonsense": 1}, ["nonsense"]),
    ):
        refused = _study(api, design={"conditions": {"a": {"run": run}}})
        assert refused.status_code == 422, refused.text
        locs = [e["loc"] for e in refused.json()["detail"]]
        assert ["body", "design", "conditions", "a", "run", *where] in locs, locs


def _bounds_unknown_to_json_schema(node: Any) -> list[str]:
    """pydantic's names for bounds (`ge`, `le`, ...) where JSON Schema's belong."""
    if isinstance(node, list):
        return [found for item in node for found in _bounds_unknown_to_json_schema(item)]
    if not isinstance(node, dict):
        return []
    here = [k for k, v in node.items() if k in ("ge", "le", "gt", "lt") and not isinstance(v, dict)]
    return here + [f for v in node.values() for f in _bounds_unknown_to_json_schema(v)]


def test_an_integer_may_be_written_with_a_zero_fraction(api: httpx.Client) -> None:
    """JSON Schema's `integer` is any number whose fraction is zero."""
    assert not _bounds_unknown_to_json_schema(api.get("/openapi.json").json())
    design = {"conditions": {"a": {"target": 133.0, "run": {"seed": 4.0}}}, "capacity": 3.0}
    created = _study(api, design=design)
    assert created.status_code == 201, created.text
    stored = created.json()["design"]
    assert stored["conditions"]["a"]["target"] == 133 and stored["capacity"] == 3
    assert stored["conditions"]["a"]["run"]["seed"] == 4

    study = created.json()["id"]
    run = {"method": "oracle", "seed": 5.0, "config": {"batch_size": 8.0}, "version": 1.0}
    session = api.post(f"/api/studies/{study}/sessions", json={"run": run})
    assert session.status_code == 201, session.text
    assert session.json()["run"]["config"]["batch_size"] == 8 and session.json()["seed"] == 5

    for bad in (133.5, True, "133"):
        refused = _study(api, design={"conditions": {"a": {"target": bad}}})
        assert refused.status_code == 422, f"{bad!r}: {refused.text}"
    refused = api.post(f"/api/studies/{study}/sessions", json={"run": {"seed": 1.5}})
    assert refused.status_code == 422, refused.text


def test_a_report_naming_sessions_the_study_lacks_is_not_found(api: httpx.Client) -> None:
    study = _study(api).json()["id"]
    response = api.post(f"/api/studies/{study}/report", json={"sessions": [987654]})
    assert response.status_code == 404, response.text
    message = response.json()["detail"]
    assert "987654 are not in study" in message
    assert f"GET /api/studies/{study}/sessions" in message


def _rule_between_fields(run: Any) -> str | None:
    """The field the run's declaration names for a run whose every value it allows alone: a
    rule between fields (`learner.fields.AtLeast`, `RunSpec.validate`, the memory this machine
    has), or None. A value refused alone fails here (pydantic's ValidationError): the
    document should have said so."""
    values = given(run_model().model_validate(run))
    if values.get("version", 0) is None:
        del values["version"]
    try:
        declared().from_json(values).validate().pinned()
    except FieldError as error:
        return f"run.{error.field}"
    return None


def _refusals_allowed(body: Any, run: Any) -> list[str]:
    """The fields a 422 may name for a body the document allows: where a rule between fields
    is broken, of the run or of the body (a participant's pseudonym is for a human run), or
    a reference to what this installation holds (an advisor's checkpoint, a fitted model)
    that names nothing, which depends on the data, not on the body's form."""
    allowed = [rule] if (rule := _rule_between_fields(run)) else []
    method = run.get("method") or "autonomous"
    if isinstance(body, dict) and body.get("participant") is not None and method != "human":
        allowed.append("participant")
    if method == "agent" and run.get("advisor_checkpoint"):
        allowed.append("run.advisor_checkpoint")
    if method == "fitted" and run.get("fitted_model"):
        allowed.append("run.fitted_model")
    return allowed


def _accepted(server: LiveServer, path: str, method: str, send: Any) -> list[str]:
    """Bodies of an operation drawn from the served document as valid, sent by `send`, each
    answer judged by schemathesis's own `positive_data_acceptance`, except a 422 that says
    what `_refusals_allowed` allows: JSON Schema cannot state a rule between fields (the
    document's descriptions say them), nor whether a reference names something."""
    schema = schemathesis.openapi.from_url(f"{server.url}/openapi.json")
    strategy = schema[path][method].as_strategy(generation_mode=GenerationMode.POSITIVE)
    refused: list[str] = []

    @drawn(case=strategy)
    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        database=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    def run(case: Any) -> None:
        response, runs = send(case)
        try:
            case.validate_response(response, checks=[positive_data_acceptance])
        except* AssertionError:  # the check's failures (schemathesis raises them in a group)
            allowed = [field for run in runs for field in _refusals_allowed(case.body, run)]
            details = response.json().get("detail") if response.status_code == 422 else None
            named = [".".join(map(str, e["loc"])) for e in details or []]
            if not named or not all(any(n.endswith(f".{a}") for a in allowed) for n in named):
                refused.append(f"{case.body!r} -> {response.status_code} {response.text[:300]}")

    run()
    return refused


def test_every_run_the_document_allows_is_accepted_or_breaks_a_rule_between_fields(
    server: LiveServer,
) -> None:
    study = _study(server.client()).json()["id"]
    headers = {"X-API-Key": API_KEY}

    def create(case: Any) -> tuple[Any, list[Any]]:
        case.path_parameters = {"study_id": study}
        case.query = {"pretrain": "false"}
        return case.call(base_url=server.url, headers=headers, timeout=60), [case.body["run"]]

    refused = _accepted(server, "/api/studies/{study_id}/sessions", "POST", create)
    assert not refused, "\n".join(refused[:10])


def test_every_condition_the_document_allows_is_accepted_or_breaks_a_rule_between_fields(
    server: LiveServer,
) -> None:
    """The design's conditions, drawn whole (their runs and targets), in a study whose other
    design fields take their defaults."""
    headers = {"X-API-Key": API_KEY}

    def create(case: Any) -> tuple[Any, list[Any]]:
        conditions = (case.body.get("design") or {}).get("conditions") or {"a": {}}
        case.body = {"name": f"valid-{uuid.uuid4().hex}", "design": {"conditions": conditions}}
        runs = [{"method": "human", **c.get("run", {})} for c in conditions.values()]
        return case.call(base_url=server.url, headers=headers, timeout=60), runs

    refused = _accepted(server, "/api/studies", "POST", create)
    assert not refused, "\n".join(refused[:10])


def test_every_report_request_the_document_allows_is_accepted(server: LiveServer) -> None:
    """In a study without sessions: a report of nothing is a 409, of sessions it lacks a
    404, both what the check allows (the study's state, not the body)."""
    study = _study(server.client()).json()["id"]
    headers = {"X-API-Key": API_KEY}

    def build(case: Any) -> tuple[Any, list[Any]]:
        case.path_parameters = {"study_id": study}
        return case.call(base_url=server.url, headers=headers, timeout=60), []

    refused = _accepted(server, "/api/studies/{study_id}/report", "POST", build)
    assert not refused, "\n".join(refused[:10])
