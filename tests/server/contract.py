"""Every response the API tests receive is checked against the served OpenAPI document:
its status must be one the operation declares, so a generated client never meets a status
it was not told about. Used by the test clients of `live.LiveServer` and the simulated
participant; a route outside the document (pages, the viewer) is not checked."""

from __future__ import annotations

import re
from functools import cache

import httpx


@cache
def _declared(base_url: str) -> tuple[tuple[re.Pattern[str], str, frozenset[str]], ...]:
    document = httpx.get(f"{base_url}/openapi.json", timeout=30).json()
    table = []
    for template, operations in document["paths"].items():
        pattern = re.compile("^" + re.sub(r"\{[^}/]+\}", r"[^/]+", template) + "$")
        for method, operation in operations.items():
            table.append((pattern, method.upper(), frozenset(operation["responses"])))
    return tuple(table)


def check_declared(response: httpx.Response) -> None:
    request = response.request
    base = f"{request.url.scheme}://{request.url.netloc.decode()}"
    for pattern, method, statuses in _declared(base):
        if method == request.method and pattern.match(request.url.path):
            assert str(response.status_code) in statuses, (
                f"{request.method} {request.url.path} answered {response.status_code}, "
                f"which the OpenAPI document does not declare ({', '.join(sorted(statuses))})"
            )
            return


def checked_client(**options: object) -> httpx.Client:
    """An httpx client whose every response must be declared by the OpenAPI document."""
    return httpx.Client(event_hooks={"response": [check_declared]}, **options)  # type: ignore[arg-type]
