"""Stable-Baselines3's DQN as a batch method: its runs become sessions like the others (the
same scale, seeds and records), and the report puts it beside autonomous DeepRL while its
audit flags it as another learner."""

from __future__ import annotations

import io
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from cli.main import main
from study.db.models import Episode, Step
from tests.runs.batch.helpers import (
    EPISODES,
    SCALE,
    Place,
    in_process,
    is_png,
    read_csv,
    sessions,
    start_ideeprl,
    study_id,
    training_totals,
)

pytest.importorskip("stable_baselines3")
pytestmark = pytest.mark.slow

STUDY = "sb3 baseline"
BATCH = ["batch", "--study", STUDY, "--methods", "autonomous", "sb3-dqn", "--agents", "2"]


@pytest.fixture(scope="module")
def sb3_batch(place: Place) -> str:
    """Two autonomous and two sb3-dqn runs at the reduced scale, run once for the module."""
    output = io.StringIO()
    with redirect_stdout(output), redirect_stderr(output):
        code = main([*BATCH, *SCALE, "--workers", "2", *place.flags])
    assert code == 0, output.getvalue()
    return output.getvalue()


def test_sb3_runs_are_finished_sessions_with_their_steps_and_episodes(
    place: Place, sb3_batch: str
) -> None:
    engine = place.engine()
    rows = sessions(engine, study_id(engine, STUDY))
    assert [s.status for s in rows] == ["finished"] * 4, [s.status_detail for s in rows]
    sb3 = [s for s in rows if s.method == "sb3-dqn"]
    assert sorted(s.seed for s in sb3) == [0, 1]
    for s in sb3:
        spec = s.spec
        assert (spec.advised, spec.advice_budget, spec.advisor_checkpoint) == (False, 0, None)
        config = {**spec.config.to_dict(), **spec.sb3}
        # The batch's scale options reach SB3's own hyperparameters.
        assert (config["sb3_batch_size"], config["sb3_buffer_size"]) == (8, 200)
        assert config["sb3_learning_starts"] == config["pretraining_steps"] == 20
        assert (config["sb3_learning_rate"], config["sb3_gamma"]) == (1e-3, 0.9)
        assert config["sb3_target_update_interval"] == 1  # the paper's learner has no target
        assert config["sb3_exploration_steps"] == 9209  # x0.9995 from 1.0 to 0.01
        assert Path(s.checkpoint_path or "").name == "final.pt"

    totals = training_totals(engine, [s.id for s in rows])
    assert {n for n, _ in totals.values()} == {EPISODES} and len(totals) == 4
    with Session(engine) as db:
        for s in sb3:
            steps = list(db.scalars(select(Step).where(Step.session_id == s.id)))
            episodes = list(db.scalars(select(Episode).where(Episode.session_id == s.id)))
            assert [t.global_step for t in steps] == list(range(1, len(steps) + 1))
            pretraining = [t for t in steps if t.stage == "pretrain"]
            training = [t for t in steps if t.stage == "train"]
            assert len(pretraining) == 20 and len(pretraining) + len(training) == len(steps)
            assert {t.action_source for t in pretraining} == {"random"}
            assert {t.action_source for t in training} <= {"exploration", "greedy"}
            assert all(t.loss is not None for t in training)  # an update after every action
            assert all(t.loss is None for t in pretraining)
            for e in episodes:
                mine = [t for t in steps if e.first_global_step <= t.global_step]
                mine = [t for t in mine if t.global_step <= e.last_global_step]
                assert len(mine) == e.steps
                assert sum(t.reward for t in mine) == pytest.approx(e.collected_reward)
                assert e.reset_seed is not None and e.advised_steps == 0

        # Same seed, same scenes: the first episode of each pair starts from the same reset.
        first = {
            (s.method, s.seed): db.scalar(
                select(Episode.reset_seed).where(
                    Episode.session_id == s.id, Episode.stage == "pretrain", Episode.episode == 1
                )
            )
            for s in rows
        }
        assert first[("autonomous", 0)] == first[("sb3-dqn", 0)] != first[("sb3-dqn", 1)]
        assert first[("autonomous", 1)] == first[("sb3-dqn", 1)]


def test_the_report_compares_sb3_and_flags_it_as_another_learner(
    place: Place, sb3_batch: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    study = study_id(engine, STUDY)
    out = tmp_path / "report"
    code, printed = in_process(place, capsys, "report", "--study", str(study), "--out", str(out))
    assert code == 0, printed

    rows = sessions(engine, study)
    totals = training_totals(engine, [s.id for s in rows])
    sb3_ids = [s.id for s in rows if s.method == "sb3-dqn"]
    agents = {int(a["session_id"]): a for a in read_csv(out / "r_t_per_agent.csv")}
    assert set(agents) == {s.id for s in rows}
    assert {agents[i]["method"] for i in sb3_ids} == {"sb3-dqn"}
    methods = {r["method"]: r for r in read_csv(out / "r_t_per_method.csv")}
    assert set(methods) == {"autonomous", "sb3-dqn"}
    mean = sum(totals[i][1] for i in sb3_ids) / len(sb3_ids)
    assert float(methods["sb3-dqn"]["R_T"]) == pytest.approx(mean)
    assert is_png(out / "figure5_reward_per_method.png")
    curves = read_csv(out / "reward_per_episode.csv")
    assert {c["method"] for c in curves} >= {"sb3-dqn"}

    settings = {r["method"]: r for r in read_csv(out / "settings_per_method.csv")}
    learner = settings["sb3-dqn"]["learner"]
    assert learner.startswith("sb3-dqn (Stable-Baselines3 DQN") and "learning_starts=20" in learner
    assert settings["autonomous"]["learner"].startswith("paper")
    report = (out / "report.md").read_text()
    assert "SB3 DQN were run under different settings (learner preset and options)" in report
    tests = read_csv(out / "t_tests.csv")
    pairs = [t for t in tests if "sb3-dqn" in (t["method_a"], t["method_b"])]
    assert pairs and all(t["withheld"] for t in pairs)  # t-tests across learners withheld


def test_the_same_command_again_finds_the_sb3_runs(
    place: Place, sb3_batch: str, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    before = [(s.id, s.finished_at) for s in sessions(engine, study_id(engine, STUDY))]
    code, out = in_process(place, capsys, *BATCH, *SCALE)
    assert code == 0, out
    assert "4 runs (2 autonomous, 2 sb3-dqn): 4 finished already" in out
    assert [(s.id, s.finished_at) for s in sessions(engine, study_id(engine, STUDY))] == before


def test_without_stable_baselines3_the_batch_says_how_to_install_it(
    place: Place, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # as if not installed
    code, out = in_process(place, capsys, "batch", "--study", "no sb3", "--methods", "sb3-dqn")
    assert code == 2, out
    assert "error: the sb3-dqn baseline needs Stable-Baselines3: pip install 'ideeprl[sb3]'" in out
    code, out = in_process(place, capsys, "batch", "--study", "no sb3", "--dry-run", *SCALE)
    assert code == 0, out  # the other methods do not need it


def _steps(place: Place, session_id: int) -> list[tuple[object, ...]]:
    """A session's steps as the learner made them (no times, no ids)."""
    columns = (Step.global_step, Step.stage, Step.action, Step.action_source, Step.reward)
    columns += (Step.truncated, Step.epsilon, Step.loss, Step.q_grab)
    with Session(place.engine()) as db:
        query = select(*columns).where(Step.session_id == session_id)
        return [tuple(row) for row in db.execute(query.order_by(Step.global_step))]


def test_a_killed_sb3_run_resumes_to_the_records_of_an_uninterrupted_one(
    place: Place, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from tests.runs.batch.test_interrupted_batch import wait_for

    episodes = 8
    run = ["--methods", "sb3-dqn", "--agents", "1", "--seed", "7", "--workers", "1"]
    run += ["--episodes", str(episodes), *SCALE[2:]]
    engine = place.engine()
    log = tmp_path / "runner.log"
    runner = start_ideeprl(place, "batch", "--study", "sb3 killed", *run, log=log)

    def checkpointed() -> bool:
        assert runner.poll() is None, log.read_text()
        try:
            rows = sessions(engine, study_id(engine, "sb3 killed"))
        except (AssertionError, OperationalError):
            return False  # no study yet (or, on a fresh database, no tables)
        return bool(rows) and rows[0].status == "running" and rows[0].checkpoint_episodes >= 1

    wait_for("the sb3-dqn run to checkpoint", checkpointed, log)
    runner.kill()
    runner.wait()
    study = study_id(engine, "sb3 killed")
    wait_for(
        "the orphaned worker to interrupt its session",
        lambda: sessions(engine, study)[0].status == "interrupted",
        log,
        timeout=60,
    )
    (interrupted,) = sessions(engine, study)
    assert interrupted.checkpoint_episodes < episodes

    code, again = in_process(place, capsys, "batch", "--study", "sb3 killed", *run)
    assert code == 0, again
    assert "1 runs (1 sb3-dqn): 1 to resume" in again
    (resumed,) = sessions(engine, study)
    assert resumed.id == interrupted.id and resumed.status == "finished"

    code, whole = in_process(place, capsys, "batch", "--study", "sb3 whole", *run)
    assert code == 0, whole
    (uninterrupted,) = sessions(engine, study_id(engine, "sb3 whole"))
    assert _steps(place, resumed.id) == _steps(place, uninterrupted.id)
    assert training_totals(engine, [resumed.id])[resumed.id][0] == episodes
