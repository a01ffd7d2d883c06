"""The door every request passes before the app: a bounded body, credentials checked
before the body is read, and JSON that Python can parse but JSON does not allow (NaN,
Infinity, numbers too large for a float or with more digits than Python converts, lone
surrogates) refused with a 422 that names the field and never repeats the value.

One pure ASGI middleware, so nothing is buffered before its checks: a body larger than
`max_body_bytes` is refused from its Content-Length at once, or as soon as the bytes read
pass the limit (chunked bodies), and memory stays bounded whatever a client sends.

What goes out passes here too: security headers on every response, and 422s that never
repeat the input. Both in and out are one module because the headers' middleware wraps the
`send` that the guard's refusals go through: the edge of the HTTP server, seen from
either side.

The pages load only their own scripts (no inline script: their configuration travels in
`<script type="application/json">` blocks, which are not run), so `script-src 'self'`
holds; style attributes (the advice meter) need `'unsafe-inline'` for styles only. The
participant's page and the dashboard's playback frame the 3-D view, relayed under
/viewer/ by this server (or from `viewer_public_url`): `frame-src` names that origin when
it is another one. No one may frame our pages (`frame-ancestors 'self'`). `/docs` loads
Swagger UI's local files with an inline script, so it gets a policy that allows that.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any
from urllib.parse import urlsplit

from fastapi import HTTPException
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import TypeAdapter
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from study.schemas.errors import readable, unknown_field, valid_fields, valid_listed
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
        guards: Mapping[str, Callable[[Request], Any]],
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


# What goes out: security headers, and validation errors that can always be sent.

DOCS_PATHS = ("/docs", "/redoc")
VIEWER_PATH = "/viewer/"
"""Where the app relays viser's client (server/viewer/proxy.py): a prebuilt bundle that
evaluates code and uses inline styles and blob workers, so it gets its own policy."""
BASE_HEADERS = [
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"SAMEORIGIN"),
    (b"referrer-policy", b"same-origin"),  # tokens are in paths: never to another site
    (b"cross-origin-opener-policy", b"same-origin"),
]


def page_policy(frame_origin: str | None) -> str:
    frames = "'self'" + (f" {frame_origin}" if frame_origin else "")
    return (
        "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
        "img-src 'self' data: blob:; connect-src 'self'; font-src 'self'; "
        f"frame-src {frames}; frame-ancestors 'self'; object-src 'none'; "
        "base-uri 'self'; form-action 'self'"
    )


def viewer_policy(framed_from_anywhere: bool) -> str:
    """The relayed viser client's policy. It is framed by our own pages; only when
    `viewer_public_url` sends browsers to another host name for it (the tests do, so that
    Chromium renders it in a process of its own) may another origin frame it."""
    ancestors = "*" if framed_from_anywhere else "'self'"
    return (
        "default-src 'self'; script-src 'self' 'unsafe-inline' 'unsafe-eval' blob:; "
        "worker-src 'self' blob:; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
        "connect-src 'self' ws: wss: data: blob:; font-src 'self' data:; "
        f"frame-ancestors {ancestors}; object-src 'none'; base-uri 'self'"
    )


FRAMING_PAGES = ("/p/", "/dashboard/sessions/")
"""The pages that frame the 3-D view: the participant's, and the dashboard's playback."""


def _viewer_elsewhere(scope: Scope) -> bool:
    app = scope.get("app")
    settings = getattr(getattr(app, "state", None), "settings", None)
    return bool(getattr(settings, "viewer_public_url", None))


DOCS_POLICY = (
    # Swagger UI's files are served from here (server/routes/docs.py); its page starts
    # them with an inline script.
    "default-src 'self'; script-src 'self' 'unsafe-inline'; "
    "style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
    "connect-src 'self'; worker-src 'self' blob:; frame-ancestors 'self'; object-src 'none'"
)


def _viewer_origin(scope: Scope) -> str | None:
    """Where the participant's page frames the 3-D view from, when not its own origin
    (`viewer_public_url` set to another host)."""
    from server.routes.pages import scene_src

    try:
        parts = urlsplit(scene_src(Request(scope)))
    except Exception:  # no app state (tests of the middleware alone): frame only ourselves
        return None
    return f"{parts.scheme}://{parts.netloc}" if parts.scheme and parts.netloc else None


class SecurityHeaders:
    """Adds the headers above to every HTTP response (CSP on HTML ones)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                names = {name.lower() for name, _ in headers}
                if scope.get("path", "").startswith(VIEWER_PATH) and _viewer_elsewhere(scope):
                    names.add(b"x-frame-options")  # framed by another host: frame-ancestors
                headers.extend(h for h in BASE_HEADERS if h[0] not in names)
                if b"content-security-policy" not in names:
                    headers.append((b"content-security-policy", self._policy(scope, headers)))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, with_headers)

    @staticmethod
    def _policy(scope: Scope, headers: list[tuple[bytes, bytes]]) -> bytes:
        path = scope.get("path", "")
        if path.startswith(DOCS_PATHS):
            return DOCS_POLICY.encode()
        if path.startswith(VIEWER_PATH):
            return viewer_policy(_viewer_elsewhere(scope)).encode()
        html = any(n.lower() == b"content-type" and v.startswith(b"text/html") for n, v in headers)
        origin = _viewer_origin(scope) if html and path.startswith(FRAMING_PAGES) else None
        if origin and origin == _own_origin(scope):
            origin = None
        return page_policy(origin).encode()


def _own_origin(scope: Scope) -> str:
    request = Request(scope)
    return f"{request.url.scheme}://{request.url.netloc}"


QUOTABLE = 12
"""Characters from which a value sent is long enough to be unmistakable in a message."""
SENT = "(the value sent)"


def _leaves(value: Any) -> set[str]:
    """Every value (string or number) under a JSON value that a message could quote, as it
    would be printed (`str` and `repr`); not the keys, which name fields."""
    stack = [value]
    found: set[str] = set()
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, str | int | float) and not isinstance(item, bool):
            found.update(p for p in (str(item), repr(item)) if len(p) >= QUOTABLE)
    return found


_NOTHING = object()


async def _json_body(request: Request) -> Any:
    """The request's body as JSON (`_NOTHING`: none, not JSON, or streamed, not kept)."""
    try:
        body = await request.body()
        return json.loads(body) if body else _NOTHING
    except (RuntimeError, ValueError):
        return _NOTHING


def _value_at(body: Any, loc: Sequence[Any]) -> Any:
    """The part of the body an error's `loc` points to (`_NOTHING` if it points nowhere);
    a step that names no key (a union member's tag) stays where it is."""
    if not loc or loc[0] != "body" or body is _NOTHING:
        return _NOTHING
    node = body
    for part in loc[1:]:
        in_list = isinstance(node, list) and isinstance(part, int) and abs(part) < len(node)
        if in_list or (isinstance(node, dict) and part in node):
            node = node[part]
    return node


def _hidden(message: str, values: set[str]) -> str:
    if len(message) < QUOTABLE:
        return message
    for value in sorted(values, key=len, reverse=True):
        message = message.replace(value, SENT)
    return message


async def without_input(request: Request, message: str) -> str:
    """`message` with every long value of the request's body taken out: a 422 says what is
    wrong with a field, never what was sent (a message built by a service or the learner's
    config may quote it)."""
    body = await _json_body(request)
    return message if body is _NOTHING else _hidden(message, _leaves(body))


def _printable(value: Any) -> Any:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return value
    return str(value).encode("utf-8", "backslashreplace").decode("utf-8")


Home = Callable[[str], str | None]
"""Where a run's field of this name belongs (e.g. `run.config.advice_budget`), or None."""
_PLAIN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,39}")
"""A field name the 422 may repeat: what a field's name looks like, and no longer."""


def _body_schema(route: Any) -> dict[str, Any] | None:
    """The JSON schema of the body `route` validates (its `loc` after "body"), or None: the
    route's own type, so routes left out of the API document (the dashboard's) have one.
    Made at a route's first such 422 and kept on the route."""
    if route is None:
        return None
    if not hasattr(route, "ideeprl_body_schema"):
        field = getattr(route, "body_field", None)
        annotation = getattr(getattr(field, "field_info", None), "annotation", None)
        try:
            schema = None if annotation is None else TypeAdapter(annotation).json_schema()
        except Exception:  # a type without a JSON schema: the message points to the document
            schema = None
        route.ideeprl_body_schema = schema
    return route.ideeprl_body_schema


def _unknown_field(
    body: Any, where: Sequence[Any], home: Home | None, valid: list[str] | None
) -> tuple[str, str]:
    """The last `loc` step and the message for an unknown field. A plain identifier is
    named, since it is what the sender has to fix, and a run's field sent in the wrong
    place (in or beside a `run`) says where it belongs; any other name is the sender's
    text and is not repeated. `valid`: the object's fields, named when there are at most
    `LISTED` (else the API document is where to look)."""
    name = where[-1]
    listed = valid_listed(valid)
    if not (isinstance(name, str) and _PLAIN_NAME.fullmatch(name)):
        return "(unknown field)", f"an unknown field; {listed}"
    parent = _value_at(body, where[:-1])
    by_a_run = "run" in where[:-1] or (isinstance(parent, dict) and "run" in parent)
    belongs = home(name) if home is not None and by_a_run else None
    if belongs is not None:
        return name, f"unknown field '{name}' here: it belongs in {belongs}"
    return name, unknown_field(name, valid)


def validation_error(
    home: Home | None = None,
) -> Callable[[Request, RequestValidationError], Awaitable[JSONResponse]]:
    """FastAPI's 422, without echoing the input: input it cannot encode (NaN, a lone
    surrogate) would turn the 422 into a 500, and a message need not repeat the input.
    `home`: where a run's field belongs, for an unknown field sent elsewhere."""

    async def handler(request: Request, error: RequestValidationError) -> JSONResponse:
        body = await _json_body(request)
        everything = set() if body is _NOTHING else _leaves(body)
        detail = []
        for e in error.errors():
            where = e.get("loc", ())
            loc = [_printable(readable(part)) for part in where]
            # only the value this error is about is hidden: the message may rightly name
            # other text the body also holds (an allowed option sent in another field)
            sent = _value_at(body, where)
            quoted = everything if sent is _NOTHING else _leaves(sent)
            msg = _hidden(_printable(e.get("msg", "")), quoted)
            if e.get("type") == "extra_forbidden" and loc:
                schema = _body_schema(request.scope.get("route"))
                on_body = tuple(where[:1]) == ("body",)
                valid = valid_fields(schema, where[1:-1]) if schema and on_body else None
                loc[-1], msg = _unknown_field(body, where, home, valid)
            kind = _printable(e.get("type", "value_error"))
            detail.append({"loc": loc, "msg": msg, "type": kind})
        return JSONResponse({"detail": detail}, status_code=422)

    return handler
