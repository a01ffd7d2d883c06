"""The OpenAPI contract a generated client can trust.

FastAPI declares a route's success and, for routes with parameters, 422; a client
generated from that raises on every other status as if it were unexpected. Here every
status a route can return is declared, all errors with one model (`ErrorBody`, FastAPI's
own `{"detail": ...}` written down), operation ids are the route functions' names
(`create_study`, not `create_study_api_studies_post`), and zip, PNG, CSV and Markdown
downloads are binary strings, listed first as `application/octet-stream` so that a client
generated with default settings reads their bytes. Done once, over the finished app, so a
new route gets the same treatment as long as its errors follow the rules below (a test
checks them).

Which errors a route can return:
- 401 and 403: the researcher key or the participant token is missing or wrong
  (the operation has a security requirement);
- 404: a path id that names nothing, a participant whose session was deleted, or an
  entry of `EXTRA_ERRORS` (`NotFound`);
- 409: the entries of `EXTRA_ERRORS` (a service's `Conflict`: a state that forbids it);
- 413: a body larger than the server accepts, refused by `server.guard` before it is read:
  any POST, PUT, PATCH or DELETE (`guard.BODY_METHODS`), whether or not the route takes a
  body (a client that sends none never meets it);
- 422: a parameter or body that does not validate (FastAPI), or a service's `Invalid`; and on
  any POST, PUT, PATCH or DELETE, a JSON body that JSON does not allow (NaN, a lone
  surrogate), refused by `server.guard` whether or not the route reads a body.
"""

from __future__ import annotations

import re
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from fastapi.routing import APIRoute

from server.guard import BODY_METHODS
from study.schemas.errors import ErrorBody

ERROR_DESCRIPTIONS: dict[int, str] = {
    401: "No credentials: the researcher key (X-API-Key) or the participant token is missing.",
    403: "Wrong credentials: the key or token is not valid.",
    404: "Nothing with that id (or not yet: e.g. no report built).",
    409: "The resource's state forbids this now (e.g. a session already running).",
    413: "The request body is larger than the server accepts (IDEEPRL_MAX_REQUEST_BYTES).",
    422: "The parameters or the body are not valid.",
}

EXTRA_ERRORS: dict[str, tuple[int, ...]] = {
    "create_study": (409,),
    "update_study": (409,),
    "delete_study": (409,),
    "delete_session": (409,),
    "condition_counts": (409,),
    "preview": (409,),
    "delete_previews": (409,),
    "delete_panel_person": (409,),
    "start_session": (409,),
    "pause_session": (409,),
    "resume_session": (409,),
    "stop_session": (409,),
    "build_report": (409,),
    "get_report": (404,),
    "get_report_file": (404,),
    "get_report_zip": (404,),
    "advice_observation": (404,),
    "participant_get_consent": (409,),
    "participant_give_consent": (409,),
    "participant_give_advice": (409,),
    "participant_give_rating": (409,),
    "participant_start": (409,),
    "participant_answer_check": (409,),
    "participant_submit_questionnaire": (409,),
}
"""Statuses a route returns beyond what its dependencies and path ids imply (by name)."""

BINARY_TYPES = ("application/zip", "image/png", "text/csv", "text/markdown")
BYTES = "application/octet-stream"

_REF = "#/components/schemas/"
PARTICIPANT_SCHEME = "HTTPBearer"
"""The participant token's security scheme (`server.deps`); the researcher's is APIKeyHeader."""


def operation_id(route: APIRoute) -> str:
    """The route function's name, what a generated client calls the method; a
    participant's routes say so (`participant_start`, not `start`)."""
    if "participant" in route.tags and not route.name.startswith("participant"):
        return f"participant_{route.name}"
    return route.name


def route_errors(operation: dict[str, Any], method: str = "") -> list[int]:
    """The error statuses an operation can return, by the rules in the module's docstring,
    read from its HTTP method and OpenAPI description (security, parameters, body) and
    `EXTRA_ERRORS`."""
    codes: set[int] = set(EXTRA_ERRORS.get(operation.get("operationId", ""), ()))
    if method.upper() in BODY_METHODS:
        codes.add(413)
    schemes = {name for need in operation.get("security", []) for name in need}
    if schemes:
        codes |= {401, 403}
    if PARTICIPANT_SCHEME in schemes:
        codes.add(404)  # the participant's session may have been deleted meanwhile
    places = {p.get("in") for p in operation.get("parameters", [])}
    if "path" in places:
        codes.add(404)
    if places or "requestBody" in operation or method.upper() in BODY_METHODS:
        codes.add(422)
    return sorted(codes)


def path_methods(schema: dict[str, Any], path: str) -> list[str]:
    """Every method the document declares at `path` (HEAD with GET), for a 405's `Allow`:
    Starlette names the first matching route's only, and this app has a route per method."""
    methods: set[str] = set()
    for template, operations in schema.get("paths", {}).items():
        parts = re.split(r"(\{[^}]+\})", template)
        pattern = "".join("[^/]+" if p.startswith("{") else re.escape(p) for p in parts)
        if re.fullmatch(pattern, path):
            methods |= {method.upper() for method in operations}
    if "GET" in methods:
        methods.add("HEAD")
    return sorted(methods)


def install(app: FastAPI) -> None:
    """Declare errors and binary bodies on first use of `app.openapi()` (FastAPI caches
    the result). Operation ids come from `operation_id`, given to `FastAPI(...)`."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = get_openapi(
                title=app.title,
                version=app.version,
                summary=app.summary,
                description=app.description,
                routes=app.routes,
            )
            app.openapi_schema = _declare(schema)
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


def _declare(schema: dict[str, Any]) -> dict[str, Any]:
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    body = ErrorBody.model_json_schema(ref_template=_REF + "{model}")
    components.update(body.pop("$defs", {}))
    components["ErrorBody"] = body
    error_content = {"application/json": {"schema": {"$ref": _REF + "ErrorBody"}}}
    for operations in schema.get("paths", {}).values():
        for method, operation in operations.items():
            codes = route_errors(operation, method)
            responses = operation.setdefault("responses", {})
            responses.pop("422", None)  # FastAPI's HTTPValidationError: one model instead
            for code in codes:
                responses[str(code)] = {
                    "description": ERROR_DESCRIPTIONS[code],
                    "content": error_content,
                }
            for response in responses.values():
                _declare_binary(response)
    for unused in ("HTTPValidationError", "ValidationError"):
        components.pop(unused, None)
    return schema


def _declare_binary(response: dict[str, Any]) -> None:
    """A download's bytes: `application/octet-stream` first, then what the server names it
    (zip, PNG, CSV, Markdown), all binary strings. Generators read a response by the first
    media type they know: openapi-python-client knows JSON, octet-stream and `text/*`, and
    would decode a PNG listed as `text/*` first as text, or skip the 200 of a zip."""
    content = response.get("content", {})
    if not any(media in BINARY_TYPES for media in content):
        return
    binary = {"type": "string", "format": "binary"}
    response["content"] = {
        BYTES: {"schema": dict(binary)},
        **{media: {**found, "schema": dict(binary)} for media, found in content.items()},
    }
