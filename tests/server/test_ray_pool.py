"""A pool's random practice on a Ray cluster of two 1-CPU nodes (`server.live.cluster`),
PostgreSQL and a storage root apart from the data folder: an online study's pooled session
practises as a Ray task, with the records of the same practice on a server that runs it
itself, and comes back to a worker of the web server at its first turn, from its
checkpoint under the storage root, to wait there for an arrival. Deleting the study
deletes that checkpoint."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import func, select

from study.db.engine import make_engine, make_session_factory
from study.db.models import Step, StudySession
from study.services.storage import session_dir
from tests.server.cluster import ON_POSTGRES
from tests.server.live import serving
from tests.server.scale import records
from tests.server.test_online_study import TINY_RUN, sessions_of
from tests.server.test_pools import ready, wait_for

ray = pytest.importorskip("ray")
pytestmark = [*ON_POSTGRES, pytest.mark.live]
FIRST_TURN = 15
"""TINY_RUN's random steps before its first advice (20 pretraining steps, 5 advised)."""


def practised(data_dir: Path, storage: Path, **settings: Any) -> tuple[StudySession, Any, bool]:
    """The pooled session of a one-condition study on a server with `settings`, once it
    waits at its first turn: its row, its records, and whether its checkpoint folder under
    `storage` was there before the study was deleted and gone after."""
    data_dir.mkdir()
    storage.mkdir()
    pools = {"pool_limit": 1, "pool_every_s": 0.5, "pool_practising": 1}
    with (
        serving(data_dir, heartbeat_s=1, storage_root=storage, **pools, **settings) as live,
        live.client() as api,
    ):
        design = {
            "conditions": {"early": {"run": {**TINY_RUN, "seed": 40}, "target": 2}},
            "pool": 1,
            "panel": {"kind": "prolific"},
        }
        study = api.post("/api/studies", json={"name": "pooled", "design": design}).json()
        session = wait_for(
            "a pooled session at its first turn",
            lambda: next((s for s in sessions_of(api, study) if s["pooled"] and ready(live, s)), 0),
            timeout=240,
        )
        engine = make_engine(live.database_url)
        factory = make_session_factory(engine)

        def steps() -> int:
            with factory() as db:
                query = select(func.count()).where(Step.session_id == session["id"])
                return int(db.scalar(query) or 0)

        wait_for("its practice stored", lambda: steps() == FIRST_TURN)
        with factory() as db:
            row = db.get(StudySession, session["id"])
        rows = records(factory, session["id"])
        engine.dispose()
        folder = session_dir(storage, session["id"])
        there = folder.is_dir()
        gone = api.delete(f"/api/studies/{study['id']}")
        assert gone.status_code == 204, gone.text
        return row, rows, there and not folder.exists()


def test_a_pool_s_practice_runs_on_the_cluster_and_its_advice_here(tmp_path: Path) -> None:
    from ray.cluster_utils import Cluster

    here, here_records, _ = practised(tmp_path / "here", tmp_path / "unused")
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    try:
        there, there_records, deleted = practised(
            tmp_path / "there", tmp_path / "shared", ray_address=cluster.address
        )
    finally:
        cluster.shutdown()
    assert [p["from_step"] for p in here.provenance] == [0], "practised in its own worker"
    assert [p["from_step"] for p in there.provenance] == [0, FIRST_TURN], (
        "practised in a Ray task, then resumed here from its checkpoint at its first turn"
    )
    assert (there.status, there.pooled, there.status_detail) == ("running", True, "")
    assert there.worker_host == socket.gethostname(), "its advice waits next to the web server"
    assert there.checkpoint_step == FIRST_TURN
    assert there.checkpoint_path.startswith(f"checkpoints/session-{there.id}/")
    assert not (tmp_path / "there" / "checkpoints").exists(), "under the storage root only"
    assert deleted, "its checkpoint under the storage root went with its study"
    assert there_records and there_records == here_records
