"""The participant view's one reach into viser's internals, pinned against the installed
viser: a websocket's path reaches the server before anything is sent, a valid token is
admitted, anything else is closed."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
import viser
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from server.live.hub import Hub
from server.viewer import ParticipantViewer, ViewerConfig
from server.viewer.connection import CLOSE_FORBIDDEN, VERIFIED_VISER, token_from_path

TOKENS = {"valid-token_1": 7}


@pytest.fixture
def viewer() -> Iterator[ParticipantViewer]:
    viewer = ParticipantViewer(ViewerConfig(port=0), Hub(), TOKENS.get)
    viewer.start()
    yield viewer
    viewer.stop()


def _open(viewer: ParticipantViewer, path: str):
    return connect(
        f"ws://127.0.0.1:{viewer.port}{path}",
        subprotocols=[f"viser-v{viser.__version__}"],
        open_timeout=20,
    )


def test_the_viser_this_was_verified_with() -> None:
    assert viser.__version__ == VERIFIED_VISER, (
        "server/viewer/connection.py reads viser's private attributes: check them, then "
        "update VERIFIED_VISER and the pin in pyproject.toml"
    )


def test_a_valid_token_is_admitted_with_its_session(viewer: ParticipantViewer) -> None:
    with _open(viewer, "/p/valid-token_1?x=1") as ws:
        deadline = time.monotonic() + 20
        while not viewer._admitted and time.monotonic() < deadline:
            time.sleep(0.05)
        assert list(viewer._admitted.values()) == [7]
        ws.recv(timeout=10)  # viser speaks to an admitted client
    deadline = time.monotonic() + 20
    while viewer._admitted and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not viewer._admitted, "forgotten once closed"


@pytest.mark.parametrize("path", ["/p/forged", "/", "/p/valid-token_1/../x", "/q/valid-token_1"])
def test_anything_else_is_closed_before_a_message(viewer: ParticipantViewer, path: str) -> None:
    with _open(viewer, path) as ws, pytest.raises(ConnectionClosed) as closed:
        ws.recv(timeout=10)
    assert closed.value.rcvd is not None and closed.value.rcvd.code == CLOSE_FORBIDDEN
    assert viewer.refused == 1 and not viewer._admitted and not viewer.views()


def test_token_from_path() -> None:
    assert token_from_path("/p/abc-_9?websocket=1") == "abc-_9"
    assert token_from_path("/p/abc/") == "abc"
    for bad in ("/p/", "/p/a b", "/p/a/b", "/x/abc", "/p/" + "a" * 101, "p/abc"):
        assert token_from_path(bad) is None, bad
