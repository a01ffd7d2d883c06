"""The 3-D view's websocket relay (`/viewer/p/TOKEN`) takes the path with or without a
trailing slash, as viser itself does: both reach viser, which judges the token."""

from __future__ import annotations

import pytest
import viser
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from tests.server.live import LiveServer

FORGED = "x" * 43


@pytest.mark.parametrize("slash", ["", "/"], ids=["bare", "trailing-slash"])
def test_the_relay_reaches_viser_with_or_without_a_trailing_slash(
    server: LiveServer, slash: str
) -> None:
    url = server.url.replace("http://", "ws://") + f"/viewer/p/{FORGED}{slash}"
    try:
        with (
            connect(
                url, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=30, close_timeout=5
            ) as socket,
            pytest.raises(ConnectionClosed) as closed,
        ):
            socket.recv(timeout=30)
    except InvalidStatus as refused:  # the relay itself refused the upgrade
        pytest.fail(f"{url}: HTTP {refused.response.status_code} instead of a relayed socket")
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 4003  # viser's "forbidden"


def test_the_viewer_client_is_sent_once_then_revalidated(server: LiveServer) -> None:
    """viser's client is the page's largest part: a reload gets a 304, not 650 KB again."""
    with server.client(key=None) as client:
        first = client.get("/viewer/")
        assert first.status_code == 200 and len(first.content) > 100_000
        etag = first.headers["etag"]
        again = client.get("/viewer/", headers={"If-None-Match": etag})
        assert again.status_code == 304 and again.content == b""
        stale = client.get("/viewer/", headers={"If-None-Match": '"another"'})
        assert stale.status_code == 200 and stale.headers["etag"] == etag


def test_serve_prints_no_address_of_viser_s_own(server: LiveServer) -> None:
    """viser prints a banner with its internal port (an empty scene stuck on "Connecting"
    when opened); people are told the platform's port alone."""
    printed = server.log.read_text()
    assert "IDeepRL study server" in printed, printed
    assert "ws://" not in printed and "viser" not in printed, printed
