"""Each step's outcome is stored; logs recorded before it was kept get theirs by replaying
their episodes from their reset seeds; rescoring reads them."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import select, update

from analysis.rescoring import rescored_totals
from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Step, StudySession
from study.services.episodes import load_training_steps
from study.services.outcomes import fill_outcomes
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.server.live import fresh_database

TINY = {"pretraining_steps": 30, "batch_size": 8, "memory_size": 300, "episodes": 3,
        "max_episode_steps": 25, "advice_budget": 10}  # fmt: skip


@pytest.mark.slow
def test_old_logs_get_their_outcomes_by_replaying_their_episodes(tmp_path: Path) -> None:
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        factory = make_session_factory(engine)
        with factory() as db:
            study = create_study(db, "outcomes")
            spec = RunSpec.from_json({
                "method": "oracle", "error_rate": 0.3, "config": TINY,
                "scenario": {"knock_off_rate": 0.3, "reward_scheme": "authors-interactive"},
            })  # fmt: skip
            session_id = create_session(db, study.id, spec).id
        assert run_session(session_id, url, WorkerOptions(data_dir=tmp_path)) == "finished"
        with factory() as db:
            recorded = list(db.scalars(
                select(Step.outcome).where(Step.session_id == session_id)
                .order_by(Step.global_step)
            ))  # fmt: skip
            assert None not in recorded and {"placed", "none"} <= set(recorded)
            steps = load_training_steps(db, [session_id])
            totals = rescored_totals(steps, {session_id: "authors-interactive"})
            assert bool(totals.loc[0, "by_outcomes"])
            db.execute(update(Step).where(Step.session_id == session_id).values(outcome=None))
            db.commit()  # a log recorded before outcomes were kept
            old = rescored_totals(load_training_steps(db, [session_id]),
                                  {session_id: "authors-interactive"})  # fmt: skip
            assert not bool(old.loc[0, "by_outcomes"])
            session = db.get(StudySession, session_id)
            assert session is not None
            filled = fill_outcomes(db, session)
            assert filled.steps == len(recorded) and filled.without_seed == 0
            again = list(db.scalars(
                select(Step.outcome).where(Step.session_id == session_id)
                .order_by(Step.global_step)
            ))  # fmt: skip
            assert again == recorded
            assert fill_outcomes(db, session).steps == 0  # nothing left to do
        engine.dispose()
