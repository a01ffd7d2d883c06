from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from tests.server.live import LiveServer, serving


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
