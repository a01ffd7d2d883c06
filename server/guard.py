"""The door every request passes before the app: a bounded body, credentials checked
before the body is read, and JSON that Python can parse but JSON does not allow (NaN,
Infinity, numbers too large for a float or with more digits than Python converts, lone
surrogates) refused with a 422 that names the field and never repeats the value.

One pure ASGI middleware, so nothing is buffered before its checks: a body larger than
`max_body_bytes` is refused from its Content-Length at once, or as soon as the bytes read
pass the limit (chunked bodies), and memory stays bounded whatever a client sends.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping
from typing import Any

from fastapi import HTTPException
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from study.schemas.types import SURROGATE_MESSAGE

BODY_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
DASHBOARD_API = "/dashboard/api/"
LOGIN = "dashboard-login"


class BodyTooLarge(HTTPException):
    """Raised from `receive` once the body passes the limit; FastAPI lets it through."""

    def __init__(self, limit: int) -> None:
        super().__init__(
            413,
            f"the request body is larger than this server accepts ({limit} bytes); "
            "send less (IDEEPRL_MAX_REQUEST_BYTES sets the limit)",
        )


class UnacceptableJson(ValueError):
    def __init__(self, message: str, loc: tuple[str | int, ...] = ()) -> None:
        super().__init__(message)
        self.loc = loc


class _NotFinite:
    """Where the parser met a number JSON cannot mean (NaN, Infinity, too large for a
    float); found again by `_check` to name its field without repeating it."""

    def __init__(self, what: str) -> None:
        self.what = what


def _finite(text: str) -> float | _NotFinite:
    value = float(text)
    return value if math.isfinite(value) else _NotFinite("is too large for a float")


def _integer(text: str) -> int | _NotFinite:
    try:
        return int(text)
    except ValueError:  # more digits than Python converts (sys.get_int_max_str_digits)
        return _NotFinite("has more digits than any field here accepts")


def _constant(name: str) -> _NotFinite:
    return _NotFinite(f"is {name}, which is not a JSON number; numbers must be finite")


def _printable(key: str) -> str:
    return key.encode("utf-8", "backslashreplace").decode()


Describe = Callable[[tuple[str | int, ...]], str | None]
"""What a body's field allows, by its path (e.g. ('run', 'config', 'batch_size')), or None."""


def _check(value: Any, describe: Describe | None = None) -> None:
    """Refuse numbers JSON has not and strings UTF-8 cannot encode (lone surrogates), keys
    included, naming where they are (and what the field allows, where `describe` knows it)
    and never what they are."""
    stack: list[tuple[Any, tuple[str | int, ...]]] = [(value, ())]
    while stack:
        item, at = stack.pop()
        if isinstance(item, _NotFinite):
            allowed = describe(at) if describe is not None else None
            if allowed:
                field = ".".join(map(str, at))
                raise UnacceptableJson(f"{field} must be {allowed}: the number {item.what}", at)
            raise UnacceptableJson(f"the number {item.what}", at)
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError:
                raise UnacceptableJson(f"Text {SURROGATE_MESSAGE}", at) from None
        elif isinstance(item, dict):
            for key, child in item.items():
                stack.append((key, at))
                stack.append((child, (*at, _printable(key))))
        elif isinstance(item, list):
            stack.extend((child, (*at, i)) for i, child in enumerate(item))


def check_json(body: bytes, describe: Describe | None = None) -> None:
    """Raise `UnacceptableJson` for JSON Python would accept but the standard does not;
    leave malformed JSON to FastAPI, which explains it."""
    try:
        parsed = json.loads(body, parse_constant=_constant, parse_float=_finite, parse_int=_integer)
    except RecursionError:
        raise UnacceptableJson("the JSON is nested too deeply") from None
    except UnicodeDecodeError:
        raise UnacceptableJson("the body is not text in UTF-8 (nor UTF-16 or UTF-32)") from None
    except ValueError:
        return
    _check(parsed, describe)


def _json_error(status: int, detail: Any, headers: Mapping[str, str] | None = None) -> Any:
    from fastapi.responses import JSONResponse

    return JSONResponse({"detail": detail}, status_code=status, headers=headers)


class RequestGuard:
    """Size limit, then credentials, then JSON sanity; see the module's docstring.

    `guards` maps an OpenAPI security scheme (`APIKeyHeader`, `HTTPBearer`) or `LOGIN`
    (the dashboard's routes) to a check run with the request before its body is read."""

    def __init__(
        self,
        app: ASGIApp,
        max_body_bytes: int,
        guards: dict[str | Callable[..., Any], Callable[[Request], Any]],
        describe: Describe | None = None,
    ) -> None:
        self.app = app
        self.describe = describe
        self.max_body_bytes = max_body_bytes
        self.guards = guards
        self._table: list[tuple[re.Pattern[str], dict[str, list[str]]]] | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] not in BODY_METHODS:
            await self.app(scope, receive, send)
            return
        limit = self.max_body_bytes
        length = _content_length(scope)
        if length is not None and length > limit:
            await _json_error(413, BodyTooLarge(limit).detail)(scope, receive, send)
            return
        try:
            await self._credentials(scope)
        except HTTPException as error:
            await _json_error(error.status_code, error.detail, error.headers)(scope, receive, send)
            return
        try:
            body = await _read(receive, limit)
        except BodyTooLarge as error:
            await _json_error(413, error.detail)(scope, receive, send)
            return
        if _is_json(scope):
            try:
                check_json(body, self.describe)
            except UnacceptableJson as error:
                loc = ["body", *error.loc]
                detail = [{"loc": loc, "msg": str(error), "type": "json_invalid"}]
                await _json_error(422, detail)(scope, receive, send)
                return
        await self.app(scope, _replay(body, receive), send)

    async def _credentials(self, scope: Scope) -> None:
        checks = self._checks(scope)
        if checks:
            request = Request(scope)
            for check in checks:
                await run_in_threadpool(check, request)

    def _checks(self, scope: Scope) -> list[Callable[[Request], Any]]:
        """The credentials a request's operation declares: read from the OpenAPI schema
        (public, and what clients see), plus the dashboard's cookie for its own routes."""
        if self._table is None:
            self._table = _security_table(scope["app"].openapi())
        path, method = scope["path"], scope["method"].lower()
        if path.startswith(DASHBOARD_API):
            return [self.guards[LOGIN]] if LOGIN in self.guards else []
        for pattern, methods in self._table:
            if method in methods and pattern.fullmatch(path):
                return [self.guards[name] for name in methods[method] if name in self.guards]
        return []


def _security_table(schema: dict[str, Any]) -> list[tuple[re.Pattern[str], dict[str, list[str]]]]:
    """(path pattern, {method: security scheme names}) for every operation."""
    table = []
    for template, operations in schema.get("paths", {}).items():
        parts = re.split(r"(\{[^}]+\})", template)
        pattern = "".join("[^/]+" if p.startswith("{") else re.escape(p) for p in parts)
        methods = {
            method: [name for requirement in op.get("security", []) for name in requirement]
            for method, op in operations.items()
            if isinstance(op, dict)
        }
        table.append((re.compile(pattern), methods))
    return table


def _content_length(scope: Scope) -> int | None:
    for name, value in scope.get("headers", []):
        if name == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None
    return None


def _is_json(scope: Scope) -> bool:
    for name, value in scope.get("headers", []):
        if name == b"content-type":
            kind = value.split(b";")[0].strip().lower()
            return kind.endswith(b"/json") or kind.endswith(b"+json")
    return True  # FastAPI may parse a body without a type as JSON


async def _read(receive: Receive, limit: int) -> bytes:
    chunks: list[bytes] = []
    size = 0
    while True:
        message = await receive()
        if message["type"] != "http.request":
            break
        chunk = message.get("body", b"")
        size += len(chunk)
        if size > limit:
            raise BodyTooLarge(limit)
        chunks.append(chunk)
        if not message.get("more_body", False):
            break
    return b"".join(chunks)


def _replay(body: bytes, receive: Receive) -> Receive:
    sent = False

    async def replay() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay
