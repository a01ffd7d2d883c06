"""The 3-D view through the platform's own HTTP port: viser's client page and its websocket
under `/viewer/`, so one origin (and one reverse proxy with HTTPS) serves a whole study.

viser listens on loopback only, on a port nobody outside needs to know. `GET /viewer/` is
viser's one-file client, with a stylesheet that hides what only a developer wants (the
control panel with its connection state, websocket URL and scene tree; the notices such as
"Software WebGL rendering detected"); `/viewer/p/TOKEN` relays the participant's websocket
to viser's `/p/TOKEN`, byte for byte, so viser itself checks the token (`connection.py`),
and its close codes (4003) reach the browser.
"""

from __future__ import annotations

import asyncio
import contextlib
import gzip
import hashlib
import logging
from functools import cache
from pathlib import Path

import viser
from fastapi import APIRouter, Request, WebSocket
from fastapi.responses import Response
from starlette.websockets import WebSocketDisconnect
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from server.viewer.connection import TOKEN_PATH

log = logging.getLogger(__name__)
router = APIRouter(prefix="/viewer", include_in_schema=False)
CLIENT_INDEX = Path(viser.__file__).parent / "client" / "build" / "index.html"
PARTICIPANT_CSS = """<style id="ideeprl-participant">
/* The participant sees the scene, not viser's developer tools. */
.mantine-Paper-root:not(:has(canvas)), .mantine-Notifications-root { display: none !important; }
</style>"""
"""Every panel but the one holding the canvas, and all notices. The control panel is a
`mantine-Paper-root` whether floating, docked or the narrow screens' bottom sheet."""
CLOSE_UPSTREAM_GONE = 1011


@cache
def client_page() -> tuple[bytes, bytes, str]:
    """viser's client with the participant stylesheet, plain and gzipped (800 KB, once),
    and its ETag."""
    html = CLIENT_INDEX.read_text(encoding="utf-8")
    assert "</head>" in html, f"{CLIENT_INDEX} is not viser's client page"
    page = html.replace("</head>", PARTICIPANT_CSS + "</head>", 1).encode()
    return page, gzip.compress(page, compresslevel=6), f'"{hashlib.sha256(page).hexdigest()[:32]}"'


@router.get("/")
def client(request: Request) -> Response:
    """The client, revalidated on every load but sent once: it is by far the page's largest
    part (650 KB on the wire, compressed by viser itself), and a participant who reloads or
    comes back from the induction gets a 304 instead."""
    plain, zipped, etag = client_page()
    headers = {"Cache-Control": "no-cache", "Vary": "Accept-Encoding", "ETag": etag}
    if etag in request.headers.get("if-none-match", ""):
        return Response(status_code=304, headers=headers)
    if "gzip" in request.headers.get("accept-encoding", ""):
        headers["Content-Encoding"] = "gzip"
        return Response(zipped, media_type="text/html; charset=utf-8", headers=headers)
    return Response(plain, media_type="text/html; charset=utf-8", headers=headers)


def upstream_host(listen_host: str) -> str:
    """Where this process reaches the viser server it started."""
    host = "127.0.0.1" if listen_host in ("", "0.0.0.0") else listen_host
    if host == "::":
        host = "::1"
    return f"[{host}]" if ":" in host else host


@router.websocket("/p/{token}")
@router.websocket("/p/{token}/")  # as viser takes it (`TOKEN_PATH`); no redirects for sockets
async def relay(websocket: WebSocket, token: str) -> None:
    """The participant's websocket, relayed to viser's (which admits or closes it)."""
    viewer = websocket.app.state.viewer
    if not TOKEN_PATH.match(f"/p/{token}") or viewer.server is None:
        await websocket.close(code=1008)
        return
    await relay_to(websocket, f"ws://{upstream_host(viewer.config.host)}:{viewer.port}/p/{token}")


async def relay_to(websocket: WebSocket, url: str) -> None:
    """Relay a browser's websocket to a viser server's `url`, both ways, until one closes;
    viser's close code and reason reach the browser."""
    offered = list(websocket.scope.get("subprotocols") or [])
    try:
        upstream = await connect(
            url,
            subprotocols=offered or None,
            max_size=None,
            compression=None,  # as viser serves it
            open_timeout=20,
            ping_interval=None,
        )
    except (OSError, InvalidStatus, TimeoutError) as error:
        log.warning("the 3-D view's server did not answer (%s)", error)
        await websocket.close(code=CLOSE_UPSTREAM_GONE)
        return
    await websocket.accept(subprotocol=upstream.subprotocol)
    async with upstream:
        to_viser = asyncio.create_task(_browser_to_viser(websocket, upstream))
        to_browser = asyncio.create_task(_viser_to_browser(upstream, websocket))
        done, pending = await asyncio.wait(
            {to_viser, to_browser}, return_when=asyncio.FIRST_COMPLETED
        )
        for task in pending:
            task.cancel()
        for task in pending:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        code, reason = to_browser.result() if to_browser in done else (1000, "")
    with contextlib.suppress(Exception):  # the browser may have gone already
        await websocket.close(code=code, reason=reason)


async def _browser_to_viser(websocket: WebSocket, upstream: ClientConnection) -> None:
    try:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            data = message.get("bytes")
            await upstream.send(data if data is not None else message.get("text", ""))
    except (WebSocketDisconnect, ConnectionClosed):
        return


async def _viser_to_browser(upstream: ClientConnection, websocket: WebSocket) -> tuple[int, str]:
    """Relays until viser closes; returns its close code and reason for the browser."""
    try:
        async for data in upstream:
            if isinstance(data, bytes):
                await websocket.send_bytes(data)
            else:
                await websocket.send_text(data)
    except ConnectionClosed:
        pass
    except (WebSocketDisconnect, RuntimeError):
        return 1000, ""
    code = upstream.close_code
    if code is None or code in (1005, 1006):  # none given, or the connection broke
        code = 1000 if code == 1005 else CLOSE_UPSTREAM_GONE
    return code, upstream.close_reason or ""
