"""Which participant a viser client is: the one place that reaches into viser's internals.

viser 1.1.1 has no public way to read the URL a client's websocket opened, and its
`ViserServer.on_client_connect` fires only after the client's first camera message. The
participant page opens the websocket at `/p/TOKEN`; viser's low-level websocket server
(`ViserServer._websock_server`) calls back on every raw connection and keeps that
connection, with its HTTP request, in `_live_connections`. Everything that touches those
private attributes is here, so a viser upgrade breaks this file, loudly, and nothing else
(tests/e2e/test_viewer_connection.py pins it against the installed viser).
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import re
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar
from urllib.parse import urlsplit

import viser

VERIFIED_VISER = "1.1.1"
TOKEN_PATH = re.compile(r"^/p/([A-Za-z0-9_-]{1,100})/?$")
CLOSE_FORBIDDEN = 4003
"""Websocket close code for a connection without a valid participant token."""


class ViserInternalsChanged(RuntimeError):
    """viser no longer has the private attributes the participant view relies on."""

    def __init__(self, what: str) -> None:
        super().__init__(
            f"viser {viser.__version__} changed its internals ({what}); the participant view "
            f"was verified with viser {VERIFIED_VISER}. Pin viser=={VERIFIED_VISER} or adapt "
            "server/viewer/connection.py"
        )


Key = TypeVar("Key")


def guarded_server(
    host: str,
    port: int,
    admit: Callable[[int], Awaitable[None]],
    forget: Callable[[int], None],
    connected: Callable[[viser.ClientHandle], None],
) -> viser.ViserServer:
    """A viser server for views opened by token: no logo, no share button, its panel
    minimised; `admit` runs on every raw websocket before any message, `forget` when one
    closes, `connected` once viser knows the client."""
    with contextlib.redirect_stdout(io.StringIO()):
        # viser prints a banner with its own address whatever `verbose` says: an internal
        # port the relay reaches, never a page for people (they use the platform's port)
        server = viser.ViserServer(host=host, port=port, verbose=False)
    server.gui.configure_theme(show_logo=False, show_share_button=False)
    server.gui.main_panel.minimize()
    refuse_share_requests(server)
    on_raw_connect(server, admit)
    on_raw_disconnect(server, forget)
    server.on_client_connect(connected)
    return server


async def admitted(
    server: viser.ViserServer,
    client_id: int,
    lookup: Callable[[str], Key | None],
    refused: Callable[[], None],
    reason: str,
) -> Key | None:
    """What the token in the client's request path names (`lookup`, run off the event loop:
    it may read the database), or None: then `refused()` is called (before the client can
    see it) and the websocket is closed with `reason`."""
    token = token_from_path(request_path(server, client_id) or "")
    found = None
    if token is not None:
        found = await asyncio.get_running_loop().run_in_executor(None, lookup, token)
    if found is None:
        refused()
        await close(server, client_id, reason)
    return found


def _websock_server(server: viser.ViserServer) -> Any:
    websock = getattr(server, "_websock_server", None)
    if websock is None or not hasattr(websock, "on_client_connect"):
        raise ViserInternalsChanged("ViserServer._websock_server.on_client_connect")
    return websock


def on_raw_connect(server: viser.ViserServer, callback: Callable[[int], Awaitable[None]]) -> None:
    """`await callback(client_id)` on viser's event loop as soon as a websocket opens,
    before any message reaches it."""

    async def connected(connection: Any) -> None:
        await callback(int(connection.client_id))

    _websock_server(server).on_client_connect(connected)


def on_raw_disconnect(server: viser.ViserServer, callback: Callable[[int], None]) -> None:
    """`callback(client_id)` on viser's event loop when a websocket closes."""
    _websock_server(server).on_client_disconnect(lambda c: callback(int(c.client_id)))


def refuse_share_requests(server: viser.ViserServer) -> None:
    """Ignore a client's request for a public share tunnel: participants reach this server
    only through their own links."""
    from viser import _messages

    _websock_server(server).unregister_handler(_messages.ShareUrlRequest)


def _connection(server: viser.ViserServer, client_id: int) -> Any:
    live = getattr(_websock_server(server), "_live_connections", None)
    if not isinstance(live, dict):
        raise ViserInternalsChanged("WebsockServer._live_connections")
    return live.get(client_id)


def request_path(server: viser.ViserServer, client_id: int) -> str | None:
    """The path (and query) the client's websocket asked for; None if it is gone."""
    connection = _connection(server, client_id)
    if connection is None:
        return None
    request = getattr(connection, "request", None)
    path = getattr(request, "path", None)
    if not isinstance(path, str):
        raise ViserInternalsChanged("ServerConnection.request.path")
    return path


async def close(server: viser.ViserServer, client_id: int, reason: str) -> None:
    """Close a client's websocket (call on viser's event loop)."""
    connection = _connection(server, client_id)
    if connection is not None:
        await connection.close(CLOSE_FORBIDDEN, reason)


def token_from_path(path: str) -> str | None:
    """The participant token of a websocket path `/p/TOKEN[?...]`, or None."""
    match = TOKEN_PATH.match(urlsplit(path).path)
    return match.group(1) if match else None
