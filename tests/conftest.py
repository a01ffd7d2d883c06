"""Marks the suite's kinds of test, so `make test-fast` can leave out what needs a live
server: a test that takes one of the fixtures below (a uvicorn server on loopback, with its
worker processes) is `live`; a module that starts its own server marks itself."""

from __future__ import annotations

import os

import pytest

# A human session made by hand practises from when it is made (the server's
# `pretrain_on_create`); in the tests its worker starts when a test asks for one. The
# servers the tests start, in this process or another, read this.
os.environ.setdefault("IDEEPRL_PRETRAIN_ON_CREATE", "false")

LIVE_FIXTURES = frozenset({"server", "api", "live"})
"""tests/server/conftest.py's live server and its client; tests/e2e/conftest.py's."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if LIVE_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.live)
