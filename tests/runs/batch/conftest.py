from __future__ import annotations

import io
from collections.abc import Iterator
from contextlib import redirect_stderr, redirect_stdout

import pytest

from cli.main import main
from tests.runs.batch.helpers import SCALE, Place
from tests.server.live import fresh_database

BASELINES = ["batch", "--study", "baselines", "--methods", "autonomous", "agent", "--agents", "2"]
"""The paper's pair of methods, two agents each, and the advisor trained first."""


@pytest.fixture(scope="session")
def place(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Place]:
    data_dir = tmp_path_factory.mktemp("batch_data")
    with fresh_database(data_dir) as url:
        yield Place(data_dir, url)


@pytest.fixture(scope="session")
def baselines(place: Place) -> str:
    """The local batch (two worker processes), run once for the tests that read it."""
    output = io.StringIO()
    with redirect_stdout(output), redirect_stderr(output):
        code = main([*BASELINES, *SCALE, "--workers", "2", *place.flags])
    assert code == 0, output.getvalue()
    return output.getvalue()
