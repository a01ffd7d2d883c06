"""Security headers on every response, and validation errors that can always be sent.

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
from typing import Any
from urllib.parse import urlsplit

from fastapi import Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

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


def _leaves(body: bytes) -> set[str]:
    """Every value (string or number) of a JSON body that a message could quote, as it
    would be printed (`str` and `repr`); not the keys, which name fields."""
    try:
        stack = [json.loads(body)]
    except ValueError:
        return set()
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


async def without_input(request: Request, message: str) -> str:
    """`message` with every long value of the request's body taken out: a 422 says what is
    wrong with a field, never what was sent (a message built by a service or the learner's
    config may quote it)."""
    try:
        body = await request.body()
    except RuntimeError:  # the body was streamed, not kept: nothing to compare with
        return message
    if len(message) < QUOTABLE or not body:
        return message
    for value in sorted(_leaves(body), key=len, reverse=True):
        message = message.replace(value, SENT)
    return message


def _printable(value: Any) -> Any:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return value
    return str(value).encode("utf-8", "backslashreplace").decode("utf-8")


async def validation_error(request: Request, error: RequestValidationError) -> JSONResponse:
    """FastAPI's 422, without echoing the input: input it cannot encode (NaN, a lone
    surrogate) would turn the 422 into a 500, and a message need not repeat the input."""
    detail = []
    for e in error.errors():
        loc = [_printable(part) for part in e.get("loc", ())]
        msg = await without_input(request, _printable(e.get("msg", "")))
        if e.get("type") == "extra_forbidden" and loc:
            # the field's name is the sender's text: say where, not what
            loc[-1] = "(unknown field)"
            msg = "an unknown field; the API document (/openapi.json) lists the valid ones"
        detail.append({"loc": loc, "msg": msg, "type": _printable(e.get("type", "value_error"))})
    return JSONResponse({"detail": detail}, status_code=422)
