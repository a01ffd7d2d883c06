"""A run is one description: a field added to `RunSpec` reaches every entry point and every
place that shows a run, with nothing else edited; no entry point declares a run field of
its own; every number is bounded where it is declared."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from analysis.audit import audit
from cli.commands import batch as batch_command
from cli.main import build_parser
from learner.fields import bounded, leaves
from learner.run import RunSpec, declare
from runs.batch import BatchSpec
from runs.batch.runner import BatchRunner, RunnerOptions
from runs.worker.worker import WorkerOptions, run_session
from server.main import create_app
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Study, StudySession
from study.schemas.sessions import SessionOptions, session_create_model
from study.services.episodes import session_settings
from study.services.export import export_study
from study.settings import Settings
from tests.server.live import API_KEY, fresh_database

TINY = [
    "--pretraining-steps", "40", "--batch-size", "8", "--memory-size", "500",
    "--episodes", "1", "--max-episode-steps", "20", "--advice-budget", "5",
]  # fmt: skip


@dataclass(frozen=True)
class Extended(RunSpec):
    """The run with one more field, as a developer would add it."""

    probe: int = bounded(7, 0, 1000)
    """A field added at test time: it must reach every entry point unchanged."""


def _subparser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices[name]  # type: ignore[no-any-return]


@pytest.fixture
def database(tmp_path: Path) -> Iterator[str]:
    with fresh_database(tmp_path) as url:
        upgrade(make_engine(url))
        yield url


@pytest.mark.slow
def test_a_field_added_to_the_run_reaches_every_entry_point_and_every_view(
    tmp_path: Path, database: str
) -> None:
    # the command lines: generated flags, their help from the docstring and the range
    assert "--probe" not in _subparser(build_parser(), "train").format_help()
    with declare(Extended):
        _reaches_every_entry_point(tmp_path, database)


def _reaches_every_entry_point(tmp_path: Path, database: str) -> None:
    parser = build_parser()
    for command in ("train", "batch"):
        text = _subparser(parser, command).format_help()
        assert "--probe N" in text and "from 0 to 1000" in text and "added at test" in text

    # the REST body and its OpenAPI schema
    settings = Settings(data_dir=tmp_path / "data", database_url=database, api_key=API_KEY)
    app = create_app(settings)
    schema = app.openapi()["components"]["schemas"]["Run"]["properties"]["probe"]
    assert (
        schema["maximum"] == 1000
        and schema["minimum"] == 0
        and "test time" in schema["description"]
    )
    with TestClient(app) as client:
        headers = {"X-API-Key": API_KEY}
        study = client.post("/api/studies", json={"name": "probe"}, headers=headers).json()["id"]
        tiny = {"pretraining_steps": 40, "batch_size": 8, "memory_size": 500, "episodes": 1,
                "max_episode_steps": 20, "advice_budget": 5}  # fmt: skip
        made = []
        for method, probe in (("autonomous", 42), ("random", 5)):
            run = {"method": method, "probe": probe, "config": tiny, "seed": 3}
            response = client.post(
                f"/api/studies/{study}/sessions", json={"run": run}, headers=headers
            )
            assert response.status_code == 201, response.text
            assert response.json()["run"]["probe"] == probe
            made.append(response.json()["id"])
        bad = client.post(
            f"/api/studies/{study}/sessions", json={"run": {"probe": 1001}}, headers=headers
        )
        assert bad.status_code == 422 and "from 0 to 1000" in bad.text

    # the batch's command line, and the sessions it creates
    args = parser.parse_args(["batch", "--study", "probe", "--methods", "autonomous",
                              "--agents", "1", "--probe", "44", *TINY])  # fmt: skip
    spec = batch_command.spec_from(args)
    assert spec.template.probe == 44  # type: ignore[attr-defined]
    runner = BatchRunner(spec, study, database, RunnerOptions(progress=False))
    runner.prepare()
    made.append(runner.states[0].session_id)

    # ideeprl train: the flag reaches the run it trains and the checkpoint it resumes from
    out = tmp_path / "train"
    args = parser.parse_args(["train", "--out", str(out), "--probe", "45", "--no-progress", *TINY])
    assert args.func(args) == 0
    resumed = parser.parse_args(["train", "--resume", str(out / "checkpoint.pt")])
    from cli.commands.train import run_spec

    assert run_spec(resumed)[0].probe == 45  # type: ignore[attr-defined]

    factory = make_session_factory(make_engine(database))
    with factory() as db:
        rows = [db.get(StudySession, i) for i in made]
        assert [r.spec.probe for r in rows] == [42, 5, 44]  # type: ignore[attr-defined, union-attr]
    # the worker rebuilds and runs it
    status = run_session(made[0], database, WorkerOptions(data_dir=tmp_path / "data"))
    assert status == "finished"

    # the export: a typed, documented column, and the whole run
    out = tmp_path / "export"
    with factory() as db:
        export_study(db, study, out, "csv")
        sessions = list(db.scalars(select(StudySession).where(StudySession.study_id == study)))
        settings_table = session_settings(sessions)
    package = json.loads((out / "datapackage.json").read_text())
    fields = {f["name"]: f for f in package["resources"][0]["schema"]["fields"]}
    assert fields["probe"]["type"] == "integer" and "test time" in fields["probe"]["description"]
    assert _column(out / "sessions.csv", "probe") == ["42", "5", "44"]
    assert sorted(json.loads(r)["probe"] for r in _column(out / "sessions.csv", "run_spec")) == [
        5,
        42,
        44,
    ]

    # the report's audit: the field is a setting compared methods must share
    assert "probe" in settings_table.columns
    checked = audit(settings_table[settings_table["session_id"].isin(made[:2])])
    assert any("probe" in what for what in checked.mismatches.values())


def _column(path: Path, name: str) -> list[str]:
    import csv

    with path.open() as f:
        return [row[name] for row in csv.DictReader(f)]


@pytest.mark.slow
def test_a_finished_batch_still_finds_its_runs_after_a_field_is_added(
    tmp_path: Path, database: str
) -> None:
    argv = ["batch", "--study", "resumes", "--methods", "autonomous", "random", "--agents", "1",
            "--data-dir", str(tmp_path / "data"), "--database-url", database,
            "--no-progress", *TINY]  # fmt: skip
    args = build_parser().parse_args(argv)
    assert args.func(args) == 0
    with declare(Extended), make_session_factory(make_engine(database))() as db:
        extended = build_parser().parse_args([*argv, "--dry-run", "--json"])
        spec = batch_command.spec_from(extended)
        study = db.scalar(select(Study).where(Study.name == "resumes"))
        assert study is not None
        rows = BatchRunner(
            spec, study.id, database, RunnerOptions(progress=False), migrate=False
        ).preview_rows()
    assert [r.status for r in rows] == ["finished", "finished"]


# --- no entry point declares a run field of its own -------------------------------------------

RUN_FIELDS = {leaf.name for leaf in leaves(RunSpec)} | {f.name for f in dataclasses.fields(RunSpec)}


def test_the_rest_body_the_batch_and_the_command_lines_define_no_run_field() -> None:
    body = session_create_model().model_fields
    assert set(body) == {"run"} | {f.name for f in dataclasses.fields(SessionOptions)}
    assert not RUN_FIELDS & {f.name for f in dataclasses.fields(SessionOptions)}
    batch_own = {f.name for f in dataclasses.fields(BatchSpec)} - {"template"}
    assert not RUN_FIELDS & batch_own, "BatchSpec restates a run field"
    parser = build_parser()
    for command in ("train", "batch"):
        sub = _subparser(parser, command)
        generated = {
            a.dest.removeprefix("spec__") for a in sub._actions if a.dest.startswith("spec__")
        }
        own = {
            a.dest
            for a in sub._actions
            if not a.dest.startswith(("spec__", "deprecated")) and a.dest != "help"
        }
        assert not RUN_FIELDS & own, f"{command} declares a run field by hand: {RUN_FIELDS & own}"
        expected = {leaf.name for leaf in leaves(RunSpec)} - (
            {"method"} if command == "batch" else set()
        )
        assert generated == expected


def test_the_batch_prints_the_command_that_describes_the_same_runs() -> None:
    """The command a batch prints to finish it (and writes into its report) describes the
    same runs: its preset included, whatever it is (`learner.run.run_flags`)."""
    for preset in ("paper", "authors"):
        argv = ["batch", "--study", "again", "--methods", "autonomous", "agent", "--agents", "2",
                "--preset", preset, "--episodes", "3", "--knock-off-rate", "0.05"]  # fmt: skip
        args = build_parser().parse_args(argv)
        spec = batch_command.spec_from(args)
        line = batch_command.command_line(args, spec)
        again = build_parser().parse_args(shlex.split(line)[1:])
        assert batch_command.spec_from(again) == spec, line


# --- every number bounded where it is declared ----------------------------------------------------

NUMBERS = [leaf for leaf in leaves(RunSpec) if leaf.kind in (int, float)]


def _cases(leaf: object) -> list[tuple[str, str]]:
    """(name, JSON text) of the values no numeric field may take."""
    low, high = leaf.minimum, leaf.maximum  # type: ignore[attr-defined]
    step = 1 if leaf.kind is int else max(1e-6, abs(high or 1) * 1e-3)  # type: ignore[attr-defined]
    cases = [
        ("nan", "NaN"),
        ("+inf", "Infinity"),
        ("-inf", "-Infinity"),
        ("400 digits", "9" * 400),
        ("true", "true"),
        ("string", '"12"'),
    ]
    if low is not None:
        below = low - step
        cases.append(("minimum - 1", json.dumps(int(below) if leaf.kind is int else below)))  # type: ignore[attr-defined]
    if high is not None:
        above = high + step
        cases.append(("maximum + 1", json.dumps(int(above) if leaf.kind is int else above)))  # type: ignore[attr-defined]
    return cases


def _body(leaf: object, text: str) -> str:
    inner = text
    for part in reversed(leaf.path):  # type: ignore[attr-defined]
        inner = f'{{"{part}": {inner}}}'
    return f'{{"run": {inner}}}'


def test_every_numeric_field_refuses_what_it_does_not_allow(server, api) -> None:  # type: ignore[no-untyped-def]
    study = api.post("/api/studies", json={"name": "bounds"}).json()["id"]
    tried = 0
    for leaf in NUMBERS:
        for name, text in _cases(leaf):
            response = api.post(
                f"/api/studies/{study}/sessions",
                content=_body(leaf, text).encode(),
                headers={"Content-Type": "application/json"},
            )
            tried += 1
            where = f"{leaf.dotted} = {name}"
            assert response.status_code == 422, (where, response.text)
            [error] = response.json()["detail"]
            assert error["loc"][-len(leaf.path) :] == list(leaf.path), (where, error)
            assert leaf.name in error["msg"] and leaf.allowed() in error["msg"], (where, error)
            assert "9999999999" not in response.text and '"12"' not in response.text, where
    assert tried >= 7 * len(NUMBERS)
    assert api.get(f"/api/studies/{study}/sessions").json() == []  # nothing was stored


MAP_RULE = ";".join(
    f"{shape}/{color}={'left' if color == 'red' else 'right'}"
    for shape in ("cube", "cylinder", "disk")
    for color in ("red", "blue")
)
"""A map sort rule as the export writes it (98 characters)."""


def test_a_map_sort_rule_goes_back_as_the_export_wrote_it(api, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    study = api.post("/api/studies", json={"name": "map rule"}).json()["id"]
    made = api.post(f"/api/studies/{study}/sessions", json={"run": {"sort_rule": MAP_RULE}})
    assert made.status_code == 201, made.text
    assert made.json()["run"]["sort_rule"]["disk/blue"] == "right"
    args = build_parser().parse_args(
        ["batch", "--study", "map", "--sort-rule", MAP_RULE, "--methods", "autonomous"]
    )
    assert (
        batch_command.spec_from(args).template.normalized().sort_rule
        == made.json()["run"]["sort_rule"]
    )
