"""The batch runner's entry point: a session made through the service layer and run to
its end in this process, without the web server."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import func, select

from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Advice, Episode, Step, StudySession
from study.services.errors import Conflict
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.server.live import fresh_database
from tests.server.scale import EPISODES, session_body

pytestmark = pytest.mark.slow


def test_run_session_runs_a_session_to_its_end_in_this_process(tmp_path: Path) -> None:
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        factory = make_session_factory(engine)
        with factory() as db:
            study = create_study(db, "batch")
            session = create_session(
                db, study.id, RunSpec.from_json(session_body("oracle", advice_budget=10)["run"])
            )
            human = create_session(
                db, study.id, RunSpec.from_json(session_body("human", advice_budget=5)["run"])
            )
        options = WorkerOptions(data_dir=tmp_path, checkpoint_every_episodes=1)

        assert run_session(session.id, url, options) == "finished"
        with factory() as db:
            done = db.get(StudySession, session.id)
            assert done is not None and done.status == "finished"
            steps = db.scalar(select(func.count()).where(Step.session_id == session.id))
            last = db.scalar(
                select(func.max(Step.global_step)).where(Step.session_id == session.id)
            )
            trained = db.scalar(
                select(func.count()).where(
                    Episode.session_id == session.id, Episode.stage == "train"
                )
            )
        assert steps == last == done.checkpoint_step and trained == EPISODES
        with factory() as db:
            advised = db.execute(
                select(Advice.global_step, Advice.greedy_action, Step.greedy_action)
                .join(
                    Step,
                    (Step.session_id == Advice.session_id)
                    & (Step.global_step == Advice.global_step),
                )
                .where(Advice.session_id == session.id)
            ).all()
        assert len(advised) == 10, "each machine advice written once, with its step"
        assert all(row[1] == row[2] for row in advised), "the greedy action of its step"
        with factory() as db:
            stored = db.execute(
                select(Advice.action, Advice.correct_action).where(Advice.session_id == session.id)
            ).all()
        assert all(action == correct for action, correct in stored), "an oracle never errs"
        assert {correct for _, correct in stored} <= {0, 1, 2, 3}, "each one known"
        assert Path(done.checkpoint_path or "").name == "final.pt"
        assert Path(done.checkpoint_path or "").is_file(), "usable as an agent advisor"

        with pytest.raises(Conflict, match="finished"):
            run_session(session.id, url, options)
        with pytest.raises(Conflict, match="human"):
            run_session(human.id, url, options)
        engine.dispose()
