"""An online study's participants, rehearsed through their links (`ideeprl rehearse`),
on a server that hands their learners to a Ray cluster of two 1-CPU nodes after their
advice: each finishes there, on a node the database names, with the records the same
participants leave on a server that trains them itself. A replay of one of them, started
through the server, trains on the cluster from its start, with the records of the same
replay trained on the server itself. The dashboard names the node each trained on."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import pytest

from cli.main import main
from learner.fitted import Count, FittedModel
from study.db.engine import make_engine, make_session_factory
from study.db.models import Advice, StudySession
from tasks.sorting import HELD
from tests.server.cluster import ON_POSTGRES
from tests.server.live import API_KEY, serving
from tests.server.scale import records, session_body, wait_for_status

ray = pytest.importorskip("ray")
pytestmark = [*ON_POSTGRES, pytest.mark.live]
BUDGET = 5
SEEDS = (21, 22)


def fitted_model(tmp_path: Path) -> Path:
    model = FittedModel(
        advice=300, sessions=[1], methods=["human"], overall=Count(300, 0),
        by_group={h: Count(100, 0) for h in HELD}, by_situation={},
        wrong_actions=[[0] * 4 for _ in range(4)], decision_time_median_s=0.2,
        decision_time_sigma=0.3, decision_time_quantiles=[], budget_used=[1.0],
    )  # fmt: skip
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model.to_json()))
    return path


def study(data_dir: Path, model: Path, capsys: pytest.CaptureFixture[str], **settings: Any) -> Any:
    """Each seed's session's rows (session, advice, records), rehearsed on a server with
    `settings`, then those of a replay of the first, started there."""
    data_dir.mkdir()
    with serving(data_dir, heartbeat_s=1, pool_limit=0, **settings) as live, live.client() as api:
        made = api.post("/api/studies", json={"name": "on a cluster"}).json()
        ids, links = [], []
        for seed in SEEDS:
            body = session_body("human", advice_budget=BUDGET, pretraining_steps=16, seed=seed)
            created = api.post(f"/api/studies/{made['id']}/sessions", json=body).json()
            ids.append(created["id"])
            links += ["--link", f"{live.url}/p/{created['participant_token']}"]
        assert main(["rehearse", "--model", str(model), *links, "--speed", "4", "--json"]) == 0
        capsys.readouterr()
        for session_id in ids:
            wait_for_status(api, session_id, {"finished"}, timeout=300)
            progress = api.get(f"/api/sessions/{session_id}/progress").json()
            assert progress["status"] == "finished" and progress["episode"] == progress["episodes"]
        where = ["--database-url", live.database_url, "--data-dir", str(data_dir)]
        made_replay = ["replay", "--session", str(ids[0]), "--no-run", *where, "--json"]
        assert main(made_replay) == 0  # a machine session, started through the server
        replay = json.loads(capsys.readouterr().out)["session_id"]
        assert api.post(f"/api/sessions/{replay}/start").status_code == 200
        wait_for_status(api, replay, {"finished"}, timeout=300)
        ids.append(replay)
        engine = make_engine(live.database_url)
        factory = make_session_factory(engine)
        with factory() as db:
            rows = [db.get(StudySession, i) for i in ids]
            advice = [
                sorted(
                    (a.advice_index, a.global_step, a.action)
                    for a in db.query(Advice).filter_by(session_id=i)
                )
                for i in ids
            ]
        done = [
            (row, given, records(factory, row.id)) for row, given in zip(rows, advice, strict=True)
        ]
        engine.dispose()
        with httpx.Client(base_url=live.url, timeout=30) as browser:  # the dashboard's rows
            assert browser.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
            overview = browser.get("/dashboard/api/overview").json()
        nodes = {s["id"]: s["node"] for study in overview for s in study["sessions"]}
        assert [nodes[row.id] for row in rows] == [row.worker_host for row in rows]
        return done


def test_rehearsed_participants_train_on_the_cluster_as_on_this_machine(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from ray.cluster_utils import Cluster

    model = fitted_model(tmp_path)
    here = study(tmp_path / "here", model, capsys)
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    try:
        there = study(tmp_path / "there", model, capsys, ray_address=cluster.address)
    finally:
        cluster.shutdown()
    for (local, local_advice, local_records), (remote, advice, rows) in zip(
        here, there, strict=True
    ):  # the participants' sessions, then the replay of the first
        assert "Ray node" not in (local.worker_host or "")
        assert "Ray node" in (remote.worker_host or ""), remote.worker_host
        assert len(advice) == BUDGET and advice == local_advice
        assert rows and rows == local_records
    assert [row.method for row, _, _ in there] == ["human", "human", "replayed"]
