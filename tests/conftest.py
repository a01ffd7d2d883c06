"""Marks the suite's kinds of test, so `make test-fast` can leave out what needs a live
server: a test that takes one of the fixtures below (a uvicorn server on loopback, with its
worker processes) is `live`; a module that starts its own server marks itself."""

from __future__ import annotations

import pytest

LIVE_FIXTURES = frozenset({"server", "api", "live"})
"""tests/server/conftest.py's live server and its client; tests/e2e/conftest.py's."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if LIVE_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.live)
