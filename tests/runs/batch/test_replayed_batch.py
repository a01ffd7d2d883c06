"""The `replayed` method: each completed session of another study re-run under the batch's
run, fed its recorded advice by order; the report shows it as an arm of its own."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import func, select
from sqlalchemy.engine import Engine

from study.db.models import Advice
from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, study_id

pytestmark = pytest.mark.slow


def _advised_study(place: Place, name: str = "advised") -> tuple[int, list[int]]:
    """A study with one finished oracle-advised session (run in this process), and a
    session that did not finish, which is not replayed."""
    from learner.run import RunSpec
    from runs.worker.worker import WorkerOptions, run_session
    from study.db.engine import make_engine, make_session_factory
    from study.db.migrate import upgrade
    from study.services.sessions import create_session
    from study.services.studies import create_study

    engine = make_engine(place.url)
    upgrade(engine)
    config = {"pretraining_steps": 20, "advice_budget": 8, "episodes": 1, "batch_size": 8,
              "memory_size": 200, "max_episode_steps": 15, "torch_threads": 1}  # fmt: skip
    spec = RunSpec.from_json({"method": "oracle", "config": config})
    with make_session_factory(engine)() as db:
        study = create_study(db, name).id
        finished = create_session(db, study, spec).id
        create_session(db, study, spec.replace(seed=1))  # never run
    engine.dispose()
    assert run_session(finished, place.url, WorkerOptions(data_dir=place.data_dir)) == "finished"
    return study, [finished]


def test_a_batch_replays_a_studys_sessions_under_its_run_and_reports_the_arm(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    source_study, sources = _advised_study(place)
    engine = place.engine()
    replayed = [
        "batch", "--study", "reuse", "--methods", "replayed", "--agents", "1",
        "--replay-study", str(source_study), "--replay-methods", "oracle",
        "--preset", "authors", "--report", str(tmp_path / "report"), *SCALE,
    ]  # fmt: skip
    code, output = in_process(place, capsys, *replayed)
    assert code == 0, output
    rows = sessions(engine, study_id(engine, "reuse"))
    replays = [s for s in rows if s.method == "replayed"]
    assert sorted(s.replay_of for s in replays) == sources
    assert all(s.status == "finished" and s.spec.preset == "authors" for s in rows)
    assert [s.seed for s in replays] == [0]  # the base seed, as agent #1 of every method
    report = (tmp_path / "report" / "report.md").read_text()
    assert "\n| replayed | 1 |" in report, report  # its row: the arm and its one session
    met, given = _met(engine, replays[0].id)
    assert given > 0 and f"{met} of {given} replayed advice met the image" in report, report
    # the same command again finds every replay: nothing new is created
    code, output = in_process(place, capsys, *replayed[:-3], *SCALE)
    assert code == 0 and len(sessions(engine, study_id(engine, "reuse"))) == 1, output


def _met(engine: Engine, session_id: int) -> tuple[int, int]:
    """A replay's advice that met the image its advisor saw, and its advice given."""
    with engine.connect() as c:
        met_image = func.count().filter(Advice.same_observation.is_(True))
        query = select(func.count(), met_image).where(
            Advice.session_id == session_id, Advice.action.is_not(None)
        )
        given, met = c.execute(query).one()
    return int(met or 0), int(given)


def test_a_report_leaves_out_unchanged_replays_unless_they_are_chosen(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """Replaying a session unchanged (the determinism check) in its own study makes no new
    agent: the report leaves it out and says so; chosen by id it is the arm `replayed`."""
    study, (source,) = _advised_study(place, "checked by a replay")
    code, output = in_process(place, capsys, "replay", "--session", str(source), "--json")
    assert code == 0, output
    (replay,) = [s for s in sessions(place.engine(), study) if s.method == "replayed"]
    code, output = in_process(
        place, capsys, "report", "--study", str(study), "--out", str(tmp_path / "default")
    )
    assert code == 0, output
    report = (tmp_path / "default" / "report.md").read_text()
    assert "| replayed |" not in report, report
    assert f"Left out session(s) {replay.id}: unchanged replay(s) of session(s) {source}" in (
        report
    )
    chosen = ["--sessions", str(source), str(replay.id), "--out", str(tmp_path / "chosen")]
    code, output = in_process(place, capsys, "report", "--study", str(study), *chosen)
    assert code == 0, output
    report = (tmp_path / "chosen" / "report.md").read_text()
    assert "\n| replayed | 1 |" in report and "unchanged replay" not in report, report
    met, given = _met(place.engine(), replay.id)
    assert met == given > 0, "unchanged, every advice meets its image"
    assert f"{given} of {given} replayed advice met the image" in report, report
