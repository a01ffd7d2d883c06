"""The export of a real batch, read the way analysts read it: pandas, pyarrow, Frictionless,
and the scenario itself replaying an episode from its exported seed and actions."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

import sim
from cli.main import main
from tests.runs.batch.helpers import Place
from tests.study.test_export_types import ARROW_TYPES

pytestmark = pytest.mark.slow  # a real batch's export, made once for the module

PANDAS_TYPES = {"integer": "Int64", "number": "float64", "boolean": "boolean", "string": "string"}


def export(place: Place, out: Path, *fmt: str) -> dict[str, Any]:
    code = main(["export", "--study", "baselines", "--out", str(out), *fmt, *place.flags])
    assert code == 0
    return json.loads((out / "datapackage.json").read_text())


@pytest.fixture(scope="module")
def csv_export(place: Place, baselines: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("export") / "csv"
    export(place, out)
    return out


def read_typed(folder: Path, resource: dict[str, Any]) -> pd.DataFrame:
    """A CSV table read with the types its data package declares."""
    fields = resource["schema"]["fields"]
    dtypes = {f["name"]: PANDAS_TYPES[f["type"]] for f in fields if f["type"] != "datetime"}
    dates = [f["name"] for f in fields if f["type"] == "datetime"]
    frame = pd.read_csv(folder / resource["path"], dtype=dtypes)
    for name in dates:
        frame[name] = pd.to_datetime(frame[name], format="ISO8601", utc=True)
    return frame


def tables(folder: Path) -> dict[str, pd.DataFrame]:
    package = json.loads((folder / "datapackage.json").read_text())
    return {r["name"]: read_typed(folder, r) for r in package["resources"]}


def test_the_data_package_validates_against_the_files(csv_export: Path) -> None:
    frictionless = pytest.importorskip("frictionless")
    report = frictionless.validate(csv_export / "datapackage.json")
    assert report.valid, report.flatten(["rowNumber", "fieldName", "type", "note"])[:10]


def test_every_column_has_a_type_and_a_description_and_quantities_a_unit(
    csv_export: Path,
) -> None:
    package = json.loads((csv_export / "datapackage.json").read_text())
    for resource in package["resources"]:
        header = (csv_export / resource["path"]).read_text().splitlines()[0].split(",")
        fields = resource["schema"]["fields"]
        assert [f["name"] for f in fields] == header
        for field in fields:
            assert field["description"] and field["description"] != "(not documented)", field
    units = {f["name"]: f.get("unit") for r in package["resources"] for f in r["schema"]["fields"]}
    assert units["response_time_s"] == "s" and units["elapsed_s"] == "s"
    assert units["collected_reward"] == "reward"
    dictionary = pd.read_csv(csv_export / "columns.csv")
    assert list(dictionary.columns) == ["file", "column", "type", "unit", "description"]
    assert len(dictionary) == sum(len(r["schema"]["fields"]) for r in package["resources"])


def test_pandas_reads_the_declared_types_and_plain_cells(csv_export: Path) -> None:
    typed = tables(csv_export)
    steps, episodes, sessions = typed["steps"], typed["episodes"], typed["sessions"]
    assert str(steps["logged_at"].dt.tz) == "UTC" and steps["elapsed_s"].min() >= 0
    # Without any dtype, pandas itself sees booleans and numbers, not text.
    plain = pd.read_csv(csv_export / "episodes.csv")
    assert plain["terminated"].dtype == bool and plain["success"].dtype == bool
    assert plain["reset_seed"].dtype == np.int64
    raw = (csv_export / "steps.csv").read_text()
    assert "True" not in raw and "False" not in raw and "+00:00" not in raw
    assert set(steps["stage"]) == set(episodes["stage"]) == {"pretrain", "train"}
    agent = sessions.loc[sessions["method"] == "agent", "session_id"]
    advised = steps[steps["session_id"].isin(agent) & steps["advised"]]
    assert len(advised) > 0 and set(advised["stage"]) == {"pretrain"}
    assert set(sessions["sort_rule"]) == {"color"}
    assert "config" not in sessions and sessions["config_batch_size"].dtype == "Int64"
    assert (sessions["config_batch_size"] == 8).all()
    assert sessions["config_target_network"].dtype == "boolean"


def test_parquet_carries_the_same_rows_with_the_declared_types(
    place: Place, baselines: str, csv_export: Path, tmp_path: Path
) -> None:
    parquet = pytest.importorskip("pyarrow.parquet")
    package = export(place, tmp_path / "parquet", "--format", "parquet")
    from_csv = tables(csv_export)
    for resource in package["resources"]:
        table = parquet.read_table(tmp_path / "parquet" / resource["path"])
        declared = {f["name"]: ARROW_TYPES[f["type"]] for f in resource["schema"]["fields"]}
        assert {f.name: str(f.type) for f in table.schema} == declared, resource["name"]
        frame = table.to_pandas()
        expected = from_csv[resource["name"]]
        assert len(frame) == len(expected)
        for name in ("session_id", "reward", "collected_reward", "action", "terminated"):
            if name in frame:
                assert frame[name].tolist() == expected[name].astype(object).tolist(), name


def test_json_names_the_folder_and_each_tables_row_count(
    place: Place, baselines: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    parquet = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "scripted"
    capsys.readouterr()
    flags = ["--format", "parquet", "--json", *place.flags]
    assert main(["export", "--study", "baselines", "--out", str(out), *flags]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert (printed["folder"], printed["format"]) == (str(out.resolve()), "parquet")
    files = {name: parquet.read_metadata(out / name).num_rows for name in printed["rows"]}
    assert printed["rows"] == files and files["sessions.parquet"] == 5
    assert files["steps.parquet"] > files["episodes.parquet"] > 0


def test_an_episode_replays_from_its_exported_seed_and_actions(csv_export: Path) -> None:
    typed = tables(csv_export)
    sessions = typed["sessions"].set_index("session_id")
    steps, episodes = typed["steps"], typed["episodes"]
    replayed = 0
    for _, episode in episodes[episodes["stage"] == "train"].iterrows():
        session = sessions.loc[episode["session_id"]]
        mine = steps[
            (steps["session_id"] == episode["session_id"])
            & (steps["stage"] == "train")
            & (steps["episode"] == episode["episode"])
        ].sort_values("episode_step")
        env = sim.SortingEnv(
            motion=session["motion"],
            sort_rule=session["sort_rule"],
            max_episode_steps=int(session["config_max_episode_steps"]),
        )
        try:
            env.reset(seed=int(episode["reset_seed"]))
            rewards = [env.step(int(a))[1] for a in mine["action"]]
        finally:
            env.close()
        assert rewards == pytest.approx(mine["reward"].tolist())
        assert sum(rewards) == pytest.approx(episode["collected_reward"])
        replayed += 1
    assert replayed >= 4  # two methods x two agents x the batch's episodes


def test_a_map_sort_rule_is_plain_text_that_parses_back() -> None:
    from study.services.export import plain_sort_rule

    rule = {f"{s}/{c}": "left" if s == "disk" else "right" for s in sim.SHAPES for c in sim.COLORS}
    text = plain_sort_rule(rule)
    assert text.startswith("cube/red=right;") and "{" not in text
    assert sim.SortRule.parse(text) == sim.SortRule.parse(rule)


def test_an_export_reads_back_as_the_database_holds_it(
    place: Place, csv_export: Path, tmp_path: Path
) -> None:
    """Each session's run comes back whole from `run_spec` (CSV and Parquet alike), and the
    analysis' tables from the export equal the database's."""
    from sqlalchemy.orm import Session

    from analysis.exported import read_export
    from study.services.episodes import (
        load_advised_steps,
        load_episodes,
        load_training_steps,
        session_settings,
    )
    from study.services.sessions import advisor_sessions
    from tests.runs.batch.helpers import sessions, study_id

    export(place, tmp_path / "parquet", "--format", "parquet")
    engine = place.engine()
    every = sessions(engine, study_id(engine, "baselines"))
    advisors = advisor_sessions(every)
    assert len(advisors) == 1  # the agent method's trained advisor: not a compared agent
    rows = [s for s in every if s.id not in advisors]
    ids = [s.id for s in rows]
    for folder in (csv_export, tmp_path / "parquet"):
        exported = read_export(folder)
        assert exported.advisors == tuple(advisors)
        assert exported.runs == {s.id: s.spec for s in rows}
        with Session(engine) as db:
            episodes = load_episodes(db, ids)
            steps = load_training_steps(db, ids)
            settings = session_settings(rows)
            advice = load_advised_steps(db, ids)
        assert len(advice) > 0, "the agent-advised sessions were advised"
        pd.testing.assert_frame_equal(exported.advice, advice, check_dtype=False)
        pd.testing.assert_frame_equal(exported.episodes, episodes, check_dtype=False)
        pd.testing.assert_frame_equal(exported.steps, steps, check_dtype=False)
        pd.testing.assert_frame_equal(exported.settings, settings)


def test_the_report_of_an_export_has_the_advice_quality_and_the_studys_name(
    csv_export: Path, tmp_path: Path
) -> None:
    from analysis.__main__ import main as analyse

    assert analyse([str(csv_export), str(tmp_path / "report")]) == 0
    report = (tmp_path / "report" / "report.md").read_text()
    assert report.startswith("# baselines: the paper's analysis\n"), report[:200]
    assert "\n## Advice quality\n" in report and "| agent-IDeepRL |" in report
    # the agents compared are the database report's: the trained advisor is left out
    sessions = pd.read_csv(csv_export / "sessions.csv")
    advisors = sessions.loc[sessions["advises"], "session_id"].tolist()
    assert len(advisors) == 1, sessions[["session_id", "method", "advises"]]
    assert f"Left out session(s) {advisors[0]}: advisor(s) trained for the agent" in report
    compared = len(sessions) - 1
    assert f"{compared} agents in 2 methods" in report, report[:600]


def test_every_exported_run_is_accepted_back_unchanged(
    place: Place, csv_export: Path, tmp_path: Path
) -> None:
    """The API takes each exported `run_spec` as a new session's `run` and stores it as it
    was; `ideeprl batch --run FILE` makes it the batch's template, unchanged."""
    import csv

    from fastapi.testclient import TestClient

    from cli.commands.batch import spec_from
    from cli.main import build_parser
    from learner.run import RunSpec
    from server.main import create_app
    from study.settings import Settings
    from tests.server.live import API_KEY

    with (csv_export / "sessions.csv").open() as f:
        documents = [json.loads(row["run_spec"]) for row in csv.DictReader(f)]
    assert {d["method"] for d in documents} == {"autonomous", "agent"}
    settings = Settings(data_dir=place.data_dir, database_url=place.url, api_key=API_KEY)
    headers = {"X-API-Key": API_KEY}
    with TestClient(create_app(settings)) as client:
        study = client.post("/api/studies", json={"name": "round trip"}, headers=headers)
        for document in documents:
            made = client.post(
                f"/api/studies/{study.json()['id']}/sessions",
                json={"run": document},
                headers=headers,
            )
            assert made.status_code == 201, made.text
            assert made.json()["run"] == document
            path = tmp_path / "run.json"
            path.write_text(json.dumps(document))
            argv = ["batch", "--study", "x", "--methods", document["method"], "--run", str(path)]
            spec = spec_from(build_parser().parse_args([*argv, *place.flags]))
            back = spec.spec_of(document["method"], document["seed"])
            assert back == RunSpec.from_json(document)


def test_an_export_never_mixes_with_what_a_folder_held(
    place: Place, baselines: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "used"
    (out / "advice").mkdir(parents=True)
    stale = out / "advice" / "session-999-advice-00000.png"  # another study's image
    stale.write_bytes(b"old")
    (out / "episodes.parquet").write_bytes(b"old")
    argv = ["export", "--study", "baselines", "--out", str(out), *place.flags]
    assert main(argv) == 2 and "not empty" in capsys.readouterr().err
    assert stale.exists(), "a refused export touches nothing"
    assert main([*argv, "--overwrite"]) == 0
    assert not stale.exists() and not (out / "episodes.parquet").exists()
    assert (out / "episodes.csv").is_file() and (out / "study.json").is_file()

    (out / "notes.txt").write_text("mine")
    assert main([*argv, "--overwrite"]) == 1 and "notes.txt" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "mine" and (out / "episodes.csv").is_file()
