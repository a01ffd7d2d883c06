"""The analysis of a study's export (`python -m analysis EXPORT OUT`) chooses its sessions as
`ideeprl report` chooses them in the database: the finished ones, saying which others it
left out and why (still under way, or ended without finishing), unless chosen by id."""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis.__main__ import main as analyse
from analysis.finished import ENDED, FINISHED, UNDER_WAY
from cli.main import main
from learner.run import RunSpec
from study.db.engine import make_engine, make_session_factory
from study.db.models import Status
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.analysis.stored import migrated_folder, training_episode

FINISHED_RUNS = {("autonomous", 1): [0.5, 1.0, 0.0, 1.5], ("autonomous", 2): [1.0, 0.5, 1.0, 0.5]}
"""Two finished sessions, four training episodes each."""


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A data folder whose database has two studies: `training` (the new user's: one
    session still training, 2 of its episodes run) and `mixed` (two finished sessions, one
    running with 2 episodes, one whose online participant declined)."""
    folder, engine = migrated_folder(tmp_path, monkeypatch)
    with make_session_factory(engine)() as db:
        alone = create_study(db, "training")
        running = create_session(db, alone.id, RunSpec(method="autonomous", seed=1))
        running.status = Status.running.value
        db.add_all([training_episode(running.id, 1, 2.0), training_episode(running.id, 2, 3.0)])
        mixed = create_study(db, "mixed")
        for (method, seed), rewards in FINISHED_RUNS.items():
            session = create_session(db, mixed.id, RunSpec(method=method, seed=seed))
            session.status = Status.finished.value
            db.add_all(training_episode(session.id, i, r) for i, r in enumerate(rewards, start=1))
        running = create_session(db, mixed.id, RunSpec(method="autonomous", seed=3))
        running.status = Status.running.value
        db.add_all([training_episode(running.id, 1, 2.0), training_episode(running.id, 2, 3.0)])
        declined = create_session(db, mixed.id, RunSpec(method="autonomous", seed=4))
        declined.status = Status.declined.value
        db.commit()
    engine.dispose()
    return folder


def _export(data_dir: Path, study: str, out: Path) -> Path:
    assert main(["export", "--study", study, "--out", str(out), "--data-dir", str(data_dir)]) == 0
    return out


def test_every_status_is_finished_under_way_or_ended() -> None:
    assert {FINISHED, *UNDER_WAY, *ENDED} == {s.value for s in Status}
    assert not set(UNDER_WAY) & set(ENDED)


def test_an_export_of_a_session_still_training_has_nothing_to_report(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    export = _export(data_dir, "training", tmp_path / "export")
    capsys.readouterr()
    out = tmp_path / "report"
    assert analyse([str(export), str(out)]) == 1, "nothing to analyse, as `ideeprl report`"
    error = capsys.readouterr().err
    assert error.startswith("error: the export has no finished session. Not finished yet: ")
    assert "session 1 (running); wait until it finishes (and export the study again), " in error
    assert "or include it as it is with `--sessions ID ...` and `--episodes N`" in error
    assert not (out / "report.md").exists()
    # chosen by id, it is analysed as it is
    assert analyse([str(export), str(out), "--sessions", "1"]) == 0
    assert "1 agent in 1 method, 2 episodes each" in (out / "report.md").read_text()


@pytest.mark.slow
def test_an_exports_analysis_leaves_out_what_the_databases_report_leaves_out(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flags = ["--study", "mixed", "--data-dir", str(data_dir)]
    assert main(["report", *flags, "--out", str(tmp_path / "database")]) == 0
    from_database = [n[6:] for n in capsys.readouterr().out.splitlines() if n.startswith("note: ")]
    export = _export(data_dir, "mixed", tmp_path / "export")
    capsys.readouterr()
    out = tmp_path / "from-export"
    assert analyse([str(export), str(out)]) == 0
    stderr = capsys.readouterr().err
    report = (out / "report.md").read_text()
    ids = {s: i for i, s in enumerate(["a", "b", "running", "declined"], start=2)}
    under_way = (
        f"Left out 1 session not finished yet: session {ids['running']} (running); wait until "
        "it finishes{after}, or include it as it is with `--sessions ID ...` and {episodes}."
    )
    ended = (
        f"Left out 1 session that ended without finishing: session {ids['declined']} "
        "(declined consent)."
    )
    for text in (stderr, report):
        after = " (and export the study again)"
        assert under_way.format(after=after, episodes="`--episodes N`") in text
        assert ended in text
    assert (
        ended in from_database
        and under_way.format(after="", episodes="`--n-episodes N`") in from_database
    )
    assert "2 agents in 1 method, 4 episodes each" in report, (
        "the finished ones, as the database's report"
    )
    assert (out / "r_t_per_agent.csv").read_text() == (
        tmp_path / "database" / "r_t_per_agent.csv"
    ).read_text()
    # chosen by id: the running one too, over the episodes every session has
    chosen = tmp_path / "chosen"
    assert analyse([str(export), str(chosen), "--sessions", "2", "3", "4", "--episodes", "2"]) == 0
    assert "3 agents in 1 method, 2 episodes each" in (chosen / "report.md").read_text()
    assert analyse([str(export), str(chosen), "--sessions", "99"]) == 2
    assert "session(s) 99 are not in the export" in capsys.readouterr().err


def test_an_exports_table_or_a_missing_path_is_a_usage_error_of_one_line(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    export = _export(data_dir, "mixed", tmp_path / "export")
    (tmp_path / "other.csv").write_text("a,b\n1,2\n")
    capsys.readouterr()
    out = str(tmp_path / "report")
    cases = {
        export / "episodes.csv": f"is a table of the export {export}; pass the export's folder",
        tmp_path / "nonexist": f"no such file or folder: {tmp_path / 'nonexist'}; pass a study's",
        tmp_path / "other.csv": "is not an episode table: it lacks column(s) session_id, method",
    }
    for path, expected in cases.items():
        assert analyse([str(path), out]) == 2, path
        error = capsys.readouterr().err
        assert error.startswith("error: ") and expected in error, error
        assert error.count("\n") == 1 and "Traceback" not in error, error


def test_sessions_of_different_lengths_are_told_the_callers_own_option(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Sessions 2 (finished, 4 episodes) and 4 (running, 2 episodes): each caller is told
    how to cut them to 2 episodes in its own terms, as a runtime error (exit 1)."""
    from study.services.errors import Conflict
    from study.services.reports import API_CHOICE, ReportRequest, build_report

    flags = ["--study", "mixed", "--data-dir", str(data_dir), "--sessions", "2", "4"]
    assert main(["report", *flags, "--out", str(tmp_path / "report")]) == 1
    error = capsys.readouterr().err
    assert "pass `--n-episodes 2` to keep the first episodes of every agent, or drop the " in (
        error
    )
    assert error.endswith("unfinished sessions.\n") and "n_episodes" not in error, error
    assert main(["report", *flags, "--n-episodes", "3", "--out", str(tmp_path / "r")]) == 1
    error = capsys.readouterr().err
    assert "fewer than the 3 asked for. Pass `--n-episodes 2` or less" in error, error
    export = _export(data_dir, "mixed", tmp_path / "export")
    capsys.readouterr()
    assert analyse([str(export), str(tmp_path / "from-export"), "--sessions", "2", "4"]) == 1
    error = capsys.readouterr().err
    assert "pass `--episodes 2` to keep the first episodes" in error, error
    engine = make_engine(f"sqlite:///{data_dir / 'ideeprl.sqlite3'}")
    with make_session_factory(engine)() as db, pytest.raises(Conflict) as refused:
        request = ReportRequest(sessions=(2, 4), choose=API_CHOICE)
        build_report(db, 2, tmp_path / "api", request)
    engine.dispose()
    assert 'pass `"n_episodes": 2` in the body to keep the first episodes' in refused.value.message
