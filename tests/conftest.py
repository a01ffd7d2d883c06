"""Marks the suite's kinds of test, so `make test-fast` can leave out what needs a live
server or a real batch: a test that takes one of the fixtures below (a uvicorn server on
loopback, with its worker processes) is `live`; one that reads the batch the session runs
once (`tests/runs/batch/conftest.py`) is `slow`; a module that starts its own server marks
itself."""

from __future__ import annotations

import os
from collections.abc import Iterator

import httpx
import pytest

from tests.server.live import LiveServer, serving

# A human session made by hand practises from when it is made (the server's
# `pretrain_on_create`); in the tests its worker starts when a test asks for one. The
# servers the tests start, in this process or another, read this.
os.environ.setdefault("IDEEPRL_PRETRAIN_ON_CREATE", "false")
# The reports the tests write, here and in the servers and commands they start, save each
# figure as PNG alone (analysis.formats.FIGURE_FORMATS_VARIABLE): the tests read the PNGs,
# and the SVG and PDF are about half of a figure's saving time. The tests of those formats
# ask for them (tests/analysis/test_report.py, test_figures.py and test_power.py,
# tests/runs/batch/test_report_api.py).
os.environ.setdefault("IDEEPRL_FIGURE_FORMATS", "png")

LIVE_FIXTURES = frozenset({"server", "api", "live"})
"""The live server below and its client; tests/e2e/conftest.py's."""
BATCH_FIXTURES = frozenset({"baselines"})
"""The local batch of two worker processes, run once for the tests that read it."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if LIVE_FIXTURES & fixtures:
            item.add_marker(pytest.mark.live)
        if BATCH_FIXTURES & fixtures:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One live server for the API tests, on a fresh database (tests make their own
    studies); the crash tests start their own. Its pools are off: a fuzzed design must not
    make sessions behind other tests (tests/server/test_pools.py starts its own)."""
    data_dir = tmp_path_factory.mktemp("study_data")
    with serving(data_dir, checkpoint_every_episodes=2, heartbeat_s=1, pool_limit=0) as live:
        yield live


@pytest.fixture
def api(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client() as client:
        yield client
