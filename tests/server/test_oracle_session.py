"""A machine-advised session end to end: create, start, watch, export; the export holds
exactly the records the learner produces for the same seed."""

from __future__ import annotations

import csv
import io
import json
import time
import zipfile
from pathlib import Path
from typing import Any

import httpx
import pyarrow.parquet as pq
import pytest

from tests import in_process
from tests.server.live import LiveServer
from tests.server.scale import EPISODES, MAX_EPISODE_STEPS, SMALL_CONFIG, export, session_body

pytestmark = pytest.mark.slow


class Collect:
    def __init__(self) -> None:
        self.steps: list[dict[str, Any]] = []
        self.episodes: list[dict[str, Any]] = []

    def on_step(self, record: Any) -> None:
        self.steps.append(record.to_dict())

    def on_episode(self, record: Any) -> None:
        self.episodes.append(record.to_dict())


def learner_records(seed: int, budget: int) -> Collect:
    """What the learner itself produces for the session's settings, in this process."""
    import sim
    from learner import DQNConfig, Trainer, make_advisor, make_strategy

    config = DQNConfig.from_dict(
        {
            **DQNConfig.preset("paper").to_dict(),
            **SMALL_CONFIG,
            "episodes": EPISODES,
            "max_episode_steps": MAX_EPISODE_STEPS,
            "advice_budget": budget,
            "torch_threads": 1,  # as the server's workers: bit-identical needs the same count
        }
    )
    env = sim.SortingEnv(motion="fast", max_episode_steps=MAX_EPISODE_STEPS)
    advisor = make_advisor("oracle", sort_rule="color", error_rate=0.0, seed=seed)
    collect = Collect()
    Trainer(
        env, config, advisor, make_strategy("early", budget), seed=seed, callbacks=[collect]
    ).run()
    return collect


def rows(data: bytes) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(data.decode())))


def test_oracle_session_runs_to_the_end_and_exports_the_learners_records(
    server: LiveServer, api: httpx.Client, tmp_path: Path
) -> None:
    study = api.post("/api/studies", json={"name": "oracle end to end"}).json()
    created = api.post(
        f"/api/studies/{study['id']}/sessions", json=session_body("oracle", advice_budget=20)
    )
    assert created.status_code == 201, created.text
    session = created.json()
    assert session["status"] == "created" and session["participant_token"] is None

    assert api.post(f"/api/sessions/{session['id']}/start").json()["status"] == "running"
    again = api.post(f"/api/sessions/{session['id']}/start")
    assert again.status_code == 409 and "running" in again.json()["detail"]

    seen: list[dict[str, Any]] = []
    while not seen or seen[-1]["status"] not in ("finished", "failed"):
        seen.append(api.get(f"/api/sessions/{session['id']}/progress").json())
        time.sleep(0.05)
    assert seen[-1]["status"] == "finished", api.get(f"/api/sessions/{session['id']}").json()
    assert seen[-1]["episode"] == EPISODES and seen[-1]["advice_given"] == 20
    assert seen[-1]["advice_left"] == 0
    assert {p["stage"] for p in seen} >= {"train"}

    curve = api.get(f"/api/sessions/{session['id']}/episodes").json()
    files = export(api, study["id"])
    reference = learner_records(seed=11, budget=20)

    steps = rows(files["steps.csv"])
    assert len(steps) == len(reference.steps)
    assert [float(r["reward"]) for r in steps] == [s["reward"] for s in reference.steps]
    assert [int(r["action"]) for r in steps] == [s["action"] for s in reference.steps]
    episodes = rows(files["episodes.csv"])
    assert len(episodes) == len(reference.episodes)
    assert [(r["stage"], float(r["collected_reward"])) for r in episodes] == [
        (e["stage"], e["collected_reward"]) for e in reference.episodes
    ]
    trained = [e for e in reference.episodes if e["stage"] == "train"]
    assert len(curve) == len(trained) == EPISODES
    assert [e["collected_reward"] for e in curve] == [e["collected_reward"] for e in trained]
    advice = rows(files["advice.csv"])
    assert len(advice) == 20 and {r["advisor"] for r in advice} == {"oracle"}
    assert all(files[r["observation_file"]].startswith(b"\x89PNG") for r in advice)

    out = tmp_path / "export"
    done = in_process.ideeprl(
        "export", "--study", str(study["id"]), "--out", str(out),
        env={"IDEEPRL_DATABASE_URL": server.database_url},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert f"steps.csv: {len(steps)} rows" in done.stdout
    for name in ("sessions.csv", "episodes.csv", "steps.csv", "advice.csv", "columns.csv"):
        assert (out / name).read_bytes() == files[name], name

    dictionary = rows(files["columns.csv"])
    documented = {(r["file"], r["column"]) for r in dictionary if r["description"]}
    for name in ("steps.csv", "episodes.csv", "advice.csv", "sessions.csv"):
        header = files[name].decode().splitlines()[0].split(",")
        assert {(name, c) for c in header} <= documented, name
    assert all(r["description"] != "(not documented)" for r in dictionary), [
        r for r in dictionary if r["description"] == "(not documented)"
    ]

    # The same export as Parquet through the API: the same rows, each column of the type its
    # data package declares, and a descriptor Frictionless accepts. (Frictionless reads
    # Parquet through pandas, which turns an integer column with a missing value into
    # floats, so the cells are checked with pyarrow; its CSV validation is in
    # tests/runs/batch/test_export_formats.py.)
    response = api.get(f"/api/studies/{study['id']}/export", params={"format": "parquet"})
    assert response.status_code == 200, response.text
    parquet_dir = tmp_path / "parquet"
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        archive.extractall(parquet_dir)
    package = json.loads((parquet_dir / "datapackage.json").read_text())
    arrow_types = {"integer": "int64", "number": "double", "boolean": "bool", "string": "string"}
    for described in package["resources"]:
        table = pq.read_table(parquet_dir / described["path"])
        for field in described["schema"]["fields"]:
            actual = str(table.schema.field(field["name"]).type)
            expected = arrow_types.get(field["type"], "timestamp[ms, tz=UTC]")
            assert actual == expected, (described["name"], field["name"], actual)
    steps_table = pq.read_table(parquet_dir / "steps.parquet")
    assert steps_table.num_rows == len(steps)
    assert steps_table.column("reward").to_pylist() == [float(r["reward"]) for r in steps]
    frictionless = pytest.importorskip("frictionless")
    errors = list(frictionless.Package.metadata_validate(package))
    assert not errors, errors[:5]
