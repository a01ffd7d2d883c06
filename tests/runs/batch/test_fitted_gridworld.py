"""A fitted advisor in the grid world: an oracle pilot of a grid world study stands in for
people, `ideeprl fit` replays its recorded episodes in the grid world to find each advice's
situation (the run's stage within the correct move) and recovers exactly its wrong advice,
and a `fitted` grid world session runs advised by the model with the task's four moves.
Sessions run in this process by the real worker."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.migrate import upgrade
from study.db.models import Advice
from study.services.sessions import create_session
from study.services.studies import create_study
from tasks import get_task
from tests.runs.batch.helpers import Place, sessions
from tests.runs.batch.helpers import in_process as run

pytestmark = pytest.mark.slow
BUDGET = 20
TINY = {"pretraining_steps": 20, "batch_size": 8, "memory_size": 200, "episodes": 2,
        "max_episode_steps": 15, "advice_budget": BUDGET}  # fmt: skip


def test_a_model_fitted_to_a_grid_world_pilot_advises_a_grid_world_session(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    upgrade(engine)
    task = get_task("gridworld")
    with Session(engine) as db:
        study = create_study(db, "grid world pilot").id
        spec = RunSpec.from_json({"task": "gridworld", "method": "oracle", "error_rate": 0.3,
                                  "decision_time_median_s": 1.5, "config": TINY})  # fmt: skip
        oracle_id = create_session(db, study, spec).id
    options = WorkerOptions(data_dir=place.data_dir)
    assert run_session(oracle_id, place.url, options) == "finished"
    (oracle,) = sessions(engine, study)

    code, out = run(place, capsys, "fit", "--study", "grid world pilot", "--methods", "oracle",
                    "--json")  # fmt: skip
    assert code == 0, out
    fitted = json.loads(out)
    model = fitted["model"]
    assert fitted["without_situation"] == 0 and model["task"] == "gridworld"
    assert model["groups"] == list(task.action_words) and model["places"] == ["pretrain", "train"]
    assert set(fitted["summary"]["error_rate_by_situation"]) == {
        f"{p}/{w}" for p in ("pretrain", "train") for w in task.action_words
    }
    draws = np.random.default_rng(oracle.seed)  # the oracle's own draws: its wrong advice
    wrong = 0
    for _ in range(BUDGET):
        wrong += draws.random() < 0.3
        draws.integers(3)
    assert model["overall"] == {"advice": BUDGET, "wrong": int(wrong)}
    advised_in = {k.split("/")[0] for k, c in model["by_situation"].items() if c["advice"]}
    assert advised_in == {"pretrain"}  # early advising: all of it before training

    with Session(engine) as db:
        spec = RunSpec.from_json({"task": "gridworld", "method": "fitted",
                                  "fitted_model": fitted["path"], "config": TINY})  # fmt: skip
        by_model = create_session(db, study, spec).id
    assert run_session(by_model, place.url, options) == "finished"
    with Session(engine) as db:
        query = select(Advice).where(Advice.session_id == by_model)
        logged = list(db.scalars(query.order_by(Advice.advice_index)))
    assert len(logged) == BUDGET and {a.advisor for a in logged} == {"fitted"}
    assert {a.action for a in logged} <= set(range(task.n_actions))
    assert all(a.decision_time_s is not None and a.decision_time_s > 0 for a in logged)
