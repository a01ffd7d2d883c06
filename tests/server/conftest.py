from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.server.live import LiveServer, fresh_database


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One live server per test module, on its own fresh database."""
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


@pytest.fixture
def tmp_data(tmp_path: Path) -> Path:
    return tmp_path
