"""The analysis of a study's export leaves out unchanged replays as `ideeprl report` does
(one rule, `analysis.replays`), and says how much of a replayed arm's advice met its image."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest

from analysis.__main__ import main as analyse
from cli.main import main
from learner.run import RunSpec
from study.db.engine import make_session_factory
from study.db.models import Advice, Status
from study.services.sessions import Replay, ReplayStream, create_session
from study.services.studies import create_study
from tests.analysis.stored import migrated_folder, training_episode

REWARDS = {1: [0.5, 1.0, 0.0, 1.5], 2: [1.0, 0.5, 1.0, 0.5]}
"""Two finished oracle-advised sessions, by seed, four training episodes each."""


def _advice(session_id: int, index: int, same: bool | None) -> Advice:
    return Advice(
        session_id=session_id, advice_index=index, global_step=index + 1, advisor="replayed",
        action=None if same is None else 1, observation_png=b"", response_time_s=0.0,
        requested_at=datetime(2026, 1, 1, tzinfo=UTC), same_observation=same,
    )  # fmt: skip


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Study `checked`: sessions 1 and 2 (oracle, finished), 3 an unchanged replay of 1
    (finished: 2 of its 3 advice met the image, a fourth request came past the stream) and
    4 a replay of 2 under another seed (changed: an agent of its own)."""
    folder, engine = migrated_folder(tmp_path, monkeypatch)
    stream = ReplayStream(source={"study": "checked", "session": 1, "export": None},
                          actions=[1, 1, 1], observation_hashes=["a", "b", "c"])  # fmt: skip
    with make_session_factory(engine)() as db:
        study = create_study(db, "checked").id
        runs = [RunSpec(method="oracle", seed=seed) for seed in REWARDS]
        sources = [create_session(db, study, run) for run in runs]
        for source in sources:
            rewards = enumerate(REWARDS[source.seed], 1)
            db.add_all(training_episode(source.id, i, r) for i, r in rewards)
        replays = [
            create_session(db, study, run.replace(method="replayed", seed=seed),
                           replay=Replay(source.id, stream))
            for run, source, seed in zip(runs, sources, (1, 7), strict=True)
        ]  # fmt: skip
        for session in [*sources, *replays]:
            session.status = Status.finished.value
        for replay, source in zip(replays, sources, strict=True):
            rewards = enumerate(REWARDS[source.seed], 1)
            db.add_all(training_episode(replay.id, i, r) for i, r in rewards)
        advice = [True, False, True, None]
        db.add_all(_advice(replays[1].id, i, same) for i, same in enumerate(advice))
        db.commit()
        assert [s.id for s in [*sources, *replays]] == [1, 2, 3, 4]
    engine.dispose()
    return folder


@pytest.mark.slow
def test_an_exports_analysis_leaves_out_unchanged_replays_as_the_databases_report(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flags = ["--study", "checked", "--data-dir", str(data_dir)]
    assert main(["report", *flags, "--out", str(tmp_path / "database")]) == 0
    from_database = [n[6:] for n in capsys.readouterr().out.splitlines() if n.startswith("note: ")]
    left_out = (
        "Left out session(s) 3: unchanged replay(s) of session(s) 1 (a check that the "
        "platform reproduces a run, the same agent again, not one of its own); choose "
        "sessions by id to include them."
    )
    met = "The replayed arm (1 replay): 2 of 3 replayed advice met the image its advisor saw"
    assert left_out in from_database
    assert any(note.startswith(met) for note in from_database), from_database
    export = tmp_path / "export"
    assert main(["export", *flags, "--out", str(export)]) == 0
    capsys.readouterr()
    out = tmp_path / "from-export"
    assert analyse([str(export), str(out)]) == 0
    assert f"note: {left_out}" in capsys.readouterr().err
    report = (out / "report.md").read_text()
    assert left_out in report and met in report, report
    assert "past the recorded advice ran out" in report or "ran out and got none" in report
    assert "\n| replayed | 1 |" in report, "the changed replay (session 4) is an agent"
    assert (out / "r_t_per_agent.csv").read_text() == (
        tmp_path / "database" / "r_t_per_agent.csv"
    ).read_text()
    # chosen by id, the unchanged replay is an agent of the arm `replayed`
    chosen = tmp_path / "chosen"
    assert analyse([str(export), str(chosen), "--sessions", "1", "2", "3"]) == 0
    report = (chosen / "report.md").read_text()
    assert "\n| replayed | 1 |" in report and "unchanged replay" not in report, report
