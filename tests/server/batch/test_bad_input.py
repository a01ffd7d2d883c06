"""Mistakes on the command line get a message that says what to do, and run nothing:
exit 2 for an option that makes no sense, 1 for what the database does not hold."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.server.batch.helpers import SCALE, Place, sessions, study_id
from tests.server.batch.helpers import in_process as run


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--methods", "autonomous", "nope"],
            "unknown method(s) 'nope'; a batch runs autonomous, agent, oracle, random",
        ),
        (["--methods", "human"], "unknown method(s) 'human' (human sessions need a participant"),
        (["--agents", "-2"], "agents must be between 1 and 10000, got -2"),
        (["--workers", "0"], "--workers must be at least 1, got 0"),
        (["--oracle-error-rate", "1.5"], "oracle error rate must be between 0 and 1, got 1.5"),
        (["--strategy", "sometimes"], "unknown strategy 'sometimes'; choose from early"),
        (["--advisor-checkpoint", "/no/such.pt"], "no advisor checkpoint at /no/such.pt"),
        (["--set", "no_such_field=1"], "unknown config field(s) no_such_field"),
        (["--address", "ray://x:1"], "--address is for the Ray backend"),
        (["--advice-budget", "30"], "early advising gives its 30 advice at the end of pretraining"),
    ],
)
def test_bad_batch_options_are_refused_with_a_reason(
    place: Place, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    code, out = run(place, capsys, "batch", "--study", "refused", *SCALE, *args)
    assert code == 2 and f"error: {message}" in out.replace("\n", " ")


def test_an_unknown_study_id_is_named_and_nothing_runs(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out = run(place, capsys, "batch", "--study", "987654", *SCALE)
    assert code == 1 and "error: no study with id 987654" in out
    assert "Give a name instead to create a study" in out
    code, out = run(place, capsys, "report", "--study", "987654", "--out", "unused")
    assert code == 1 and "error: no study with id 987654" in out
    assert not Path("unused").exists()


def test_a_study_with_nothing_finished_says_how_to_fill_it(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, out = run(place, capsys, "batch", "--study", "still empty", *SCALE, "--dry-run")
    assert code == 0 and "new study" in out
    study = study_id(place.engine(), "still empty")
    assert sessions(place.engine(), study) == []  # a dry run creates no session
    code, out = run(place, capsys, "report", "--study", str(study), "--out", str(tmp_path / "r"))
    assert code == 1 and "no finished sessions to analyse; run sessions first" in out
    assert f"ideeprl batch --study {study}" in out
    assert not (tmp_path / "r").exists()


def test_report_sessions_must_belong_to_the_study(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    run(place, capsys, "batch", "--study", "other", *SCALE, "--dry-run")
    study = study_id(place.engine(), "other")
    code, out = run(
        place, capsys, "report", "--study", str(study), "--sessions", "424242",
        "--out", str(tmp_path / "r"),
    )  # fmt: skip
    assert code == 2 and f"session(s) 424242 are not in study {study}" in out
