"""A pool's random practice on a Ray cluster of two 1-CPU nodes (`server.live.cluster`),
PostgreSQL and a storage root apart from the data folder: an online study's pooled session
practises as a Ray task, with the records of the same practice on a server that runs it
itself, and comes back to a worker of the web server at its first turn, from its
checkpoint under the storage root, to wait there for an arrival. Deleting the study
deletes that checkpoint. While it practises there it holds one of the trainer slots, so a
participant whose advice is over waits in line behind it, and its readiness shows the
steps its task has stored."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import func, select

from learner.run import RunSpec
from runs.worker.cluster import TRAINS_ON
from study.db.engine import make_engine, make_session_factory
from study.db.models import Step, StudySession
from study.services.storage import session_dir
from tests.server.cluster import ON_POSTGRES
from tests.server.live import serving
from tests.server.participant import SimulatedParticipant
from tests.server.scale import records, session_body, wait_for_status
from tests.server.test_online_study import TINY_RUN, sessions_of
from tests.server.test_pools import ready, wait_for

ray = pytest.importorskip("ray")
pytestmark = [*ON_POSTGRES, pytest.mark.live]
FIRST_TURN = 15
"""TINY_RUN's random steps before its first advice (20 pretraining steps, 5 advised)."""
LONG_PRACTICE = {**TINY_RUN, "config": {**TINY_RUN["config"], "pretraining_steps": 3000}}
"""A practice that lasts beyond the seconds the test takes to pause it midway."""


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


def test_a_practice_on_the_cluster_holds_a_trainer_slot_and_shows_its_steps(
    tmp_path: Path,
) -> None:
    """On a cluster of one 1-CPU node (one trainer slot), a pool's practice paused midway
    holds the slot: a participant whose advice is over is queued behind it, first in line,
    and the practising session's readiness shows the steps its task stored. Resumed, the
    practice ends at its first turn, the session comes back here, and the slot goes to the
    queued participant, whose learner trains on the cluster."""
    from ray.cluster_utils import Cluster

    data_dir, storage = tmp_path / "data", tmp_path / "shared"
    data_dir.mkdir()
    storage.mkdir()
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.wait_for_nodes()
    pools = {"pool_limit": 1, "pool_every_s": 0.5, "pool_practising": 1}
    try:
        with (
            serving(
                data_dir,
                heartbeat_s=1,
                storage_root=storage,
                ray_address=cluster.address,
                **pools,
            ) as live,
            live.client() as api,
        ):
            run = {**LONG_PRACTICE, "seed": 40}
            design = {
                "conditions": {"early": {"run": run, "target": 2}},
                "pool": 1,
                "panel": {"kind": "prolific"},
            }
            study = api.post("/api/studies", json={"name": "pooled", "design": design}).json()
            pooled = wait_for(
                "a pool's practice on the cluster",
                lambda: next(
                    (
                        s
                        for s in sessions_of(api, study)
                        if s["pooled"] and s["status_detail"].startswith(TRAINS_ON)
                    ),
                    None,
                ),
                timeout=240,
            )
            pooled_id = pooled["id"]

            def progress(session_id: int) -> dict[str, Any]:
                return dict(api.get(f"/api/sessions/{session_id}/progress").json())

            wait_for("steps of it stored", lambda: progress(pooled_id)["global_step"] > 0)
            paused = api.post(f"/api/sessions/{pooled_id}/pause")
            assert paused.status_code == 200, paused.text
            halted = wait_for(
                "paused at a step boundary, checkpointed",
                lambda: next(
                    (
                        s
                        for s in [api.get(f"/api/sessions/{pooled_id}").json()]
                        if s["status"] == "paused" and s["checkpoint_step"] > 0
                    ),
                    None,
                ),
            )
            first_turn = RunSpec.from_json(run).steps_before_first_turn()
            assert 0 < halted["checkpoint_step"] < first_turn, "paused midway"
            token = pooled["participant_url"].rsplit("/", 1)[1]
            with live.client(key=None, token=token) as participant:
                shown = participant.get("/api/participant/readiness").json()
            assert shown == {
                "status": "paused",
                "steps_done": halted["checkpoint_step"],
                "steps_before_first_turn": first_turn,
                "ready": False,
            }, "its steps as its task stored them"

            lab = api.post("/api/studies", json={"name": "lab"}).json()
            body = session_body("human", advice_budget=2, episodes=1)
            person = api.post(f"/api/studies/{lab['id']}/sessions", json=body).json()
            advising = SimulatedParticipant(live.url, person["participant_token"])
            advising.begin()
            for index in range(2):
                state = advising.next_request()
                assert state["advice_index"] == index, state
                assert advising.advise(index, index % 4).status_code == 200
            wait_for("its advice over, in line", lambda: progress(person["id"])["queued"])
            queued = api.get(f"/api/sessions/{person['id']}").json()
            assert (queued["status"], queued["queue_place"]) == ("queued", 1), (
                "the practice holds the one slot"
            )
            curve = advising.client.get("/api/participant/learning-curve").json()
            assert curve["queue_place"] == 1 and curve["wait_s"] is not None, (
                "the wait counts the practice's steps left"
            )

            resumed = api.post(f"/api/sessions/{pooled_id}/resume")
            assert resumed.status_code == 200, resumed.text
            wait_for("back here at its first turn", lambda: ready(live, pooled), timeout=240)
            wait_for_status(api, person["id"], {"finished"}, timeout=300)
            engine = make_engine(live.database_url)
            with make_session_factory(engine)() as db:
                row = db.get(StudySession, person["id"])
                assert row is not None and "Ray node" in (row.worker_host or ""), "on the cluster"
            engine.dispose()
            back = api.get(f"/api/sessions/{pooled_id}").json()
            assert (back["status"], back["pooled"]) == ("running", True)
            assert back["checkpoint_step"] == first_turn
            advising.client.close()
    finally:
        cluster.shutdown()
