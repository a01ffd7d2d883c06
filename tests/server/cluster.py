"""What the Ray cluster's test modules share (test_ray_cluster.py, test_ray_pool.py,
test_ray_study.py): a cluster needs a database every node reaches, so they run against
PostgreSQL only (`DATABASE_URL`, as CI's PostgreSQL stage sets it) and skip without it."""

from __future__ import annotations

import os

import pytest

ON_POSTGRES = [
    pytest.mark.postgres,
    pytest.mark.skipif(
        not os.environ.get("DATABASE_URL", "").startswith("postgres"),
        reason="a cluster needs a database every node reaches: set DATABASE_URL to PostgreSQL",
    ),
]
"""The marks of a cluster test module (its `pytestmark`, with `live` where it starts a
server)."""
