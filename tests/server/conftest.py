from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from tests.server.live import LiveServer, fresh_database


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One live server for the API tests, on a fresh database (tests make their own
    studies); the crash tests start their own."""
    data_dir = tmp_path_factory.mktemp("study_data")
    with fresh_database(data_dir) as url:
        live = LiveServer(data_dir, url, checkpoint_every_episodes=2, heartbeat_s=1).start()
        try:
            yield live
        finally:
            live.stop()


@pytest.fixture
def api(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client() as client:
        yield client
