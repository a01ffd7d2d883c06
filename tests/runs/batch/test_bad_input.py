"""Mistakes on the command line get a message that says what to do, and run nothing:
exit 2 for an option that makes no sense, 1 for what the database does not hold."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from study.db.migrate import upgrade
from study.db.models import Study
from study.services.studies import create_study
from tests.runs.batch.helpers import SCALE, Place, sessions
from tests.runs.batch.helpers import in_process as run


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--methods", "autonomous", "nope"],
            "unknown method(s) 'nope'; a batch runs autonomous, agent, oracle, random",
        ),
        (["--methods", "human"], "unknown method(s) 'human' (human sessions need a participant"),
        (["--agents", "-2"], "agents must be between 1 and 10000, got -2"),
        (["--workers", "0"], "--workers must be at least 1"),
        (["--population", "0"], "--population must be at least 1"),
        (["--error-rate", "1.5"], "argument --error-rate: error_rate must be a number from 0 to 1"),
        (["--oracle-error-rate", "1.5"], "error_rate must be a number from 0 to 1"),  # old name
        (["--strategy", "sometimes"], 'argument --strategy: strategy must be one of "early"'),
        (
            ["--batch-size", "0"],
            "argument --batch-size: config.batch_size must be an integer from 1",
        ),
        (
            ["--set", "memory_size=1e400"],
            "config.memory_size must be an integer from 1 to 10000000",
        ),
        (["--advisor-checkpoint", "/no/such.pt"], "no advisor checkpoint at the path given"),
        (
            ["--methods", "autonomous", "--error-rate", "0.3"],
            "an error rate is only used by the 'oracle' method",
        ),
        (["--set", "no_such_field=1"], "--set: unknown field no_such_field"),
        (["--per-method", "agent:no_such=1"], "--per-method: unknown field no_such"),
        (["--per-method", "random:reward_scheme=paper"], "settings are given for random"),
        (["--address", "ray://x:1"], "--address is for the Ray backend"),
        (["--advice-budget", "30"], "agent: early advising gives its 30 advice at the end of"),
    ],
)
def test_bad_batch_options_are_refused_with_a_reason(
    place: Place, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    code, out = run(place, capsys, "batch", "--study", "refused", *SCALE, *args)
    assert code == 2 and f"error: {message}" in out.replace("\n", " ")
    upgrade(place.engine())
    with Session(place.engine()) as db:  # refused before anything was written
        assert db.scalar(select(Study).where(Study.name == "refused")) is None


def test_an_unknown_study_id_is_named_and_nothing_runs(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out = run(place, capsys, "batch", "--study", "987654", *SCALE)
    assert code == 1 and "error: no study with id 987654" in out
    assert "Give a name instead to create a study" in out
    code, out = run(place, capsys, "report", "--study", "987654", "--out", "unused")
    assert code == 1 and "error: no study with id 987654" in out
    assert not Path("unused").exists()


def test_a_dry_run_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    place = Place(tmp_path / "data", f"sqlite:///{tmp_path / 'data' / 'study.sqlite3'}")
    code, out = run(
        place, capsys, "batch", "--study", "never", *SCALE, "--agents", "1", "--dry-run", "--json"
    )
    assert code == 0 and not (tmp_path / "data").exists()  # not even a database
    planned = json.loads(out[out.index("{") :])
    assert [r["status"] for r in planned["runs"]] == ["new"] * 3  # the advisor, two agents
    assert planned["study"] is None and planned["runs"][0]["run"] == "advisor"
    # An id names no new study, with a database or without: as the real run says.
    code, out = run(place, capsys, "batch", "--study", "987654", *SCALE, "--dry-run")
    assert code == 1 and "error: no study with id 987654" in out
    assert not (tmp_path / "data").exists()


def test_a_study_with_nothing_finished_says_how_to_fill_it(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, out = run(place, capsys, "batch", "--study", "still empty", *SCALE, "--dry-run")
    assert code == 0 and "new study" in out and "not created" in out
    assert run(place, capsys, "batch", "--study", "still empty", *SCALE, "--agents", "0")[0] == 2
    with Session(place.engine()) as db:
        study = create_study(db, "still empty").id
    assert sessions(place.engine(), study) == []
    code, out = run(place, capsys, "report", "--study", str(study), "--out", str(tmp_path / "r"))
    assert code == 1 and f"study {study} has no sessions yet: run some first" in out
    assert f"ideeprl batch --study {study}" in out
    assert not (tmp_path / "r").exists()


def test_report_sessions_must_belong_to_the_study(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    upgrade(place.engine())
    with Session(place.engine()) as db:
        study = create_study(db, "other").id
    code, out = run(
        place, capsys, "report", "--study", str(study), "--sessions", "424242",
        "--out", str(tmp_path / "r"),
    )  # fmt: skip
    assert code == 2 and f"session(s) 424242 are not in study {study}" in out
