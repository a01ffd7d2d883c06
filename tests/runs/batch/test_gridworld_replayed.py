"""Recorded advice of a grid world study replayed into other learners: `ideeprl batch
--methods replayed` re-runs its finished session in the grid world under another preset,
fed the recorded moves by order."""

from __future__ import annotations

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.migrate import upgrade
from study.db.models import Advice
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, study_id

pytestmark = pytest.mark.slow


def _advice(place: Place, session_id: int) -> list[Advice]:
    with Session(place.engine()) as db:
        query = select(Advice).where(Advice.session_id == session_id)
        return list(db.scalars(query.order_by(Advice.advice_index)))


def test_a_grid_world_sessions_advice_is_replayed_into_another_learner(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    upgrade(engine)
    config = {"pretraining_steps": 20, "advice_budget": 8, "episodes": 1, "batch_size": 8,
              "memory_size": 200, "max_episode_steps": 15, "torch_threads": 1}  # fmt: skip
    spec = RunSpec.from_json(
        {"task": "gridworld", "method": "oracle", "error_rate": 0.25, "config": config}
    )
    with Session(engine) as db:
        source_study = create_study(db, "grid world advice").id
        source = create_session(db, source_study, spec).id
    assert run_session(source, place.url, WorkerOptions(data_dir=place.data_dir)) == "finished"
    recorded = [a.action for a in _advice(place, source)]
    assert len(recorded) == 8 and set(recorded) <= set(range(4))

    replayed = [
        "batch", "--study", "grid world reuse", "--task", "gridworld", "--methods", "replayed",
        "--agents", "1", "--replay-study", str(source_study), "--replay-methods", "oracle",
        "--preset", "modern", *SCALE,
    ]  # fmt: skip
    code, output = in_process(place, capsys, *replayed)
    assert code == 0, output
    (replay,) = sessions(engine, study_id(engine, "grid world reuse"))
    assert replay.replay_of == source and replay.status == "finished"
    assert replay.spec.task == "gridworld" and replay.spec.preset == "modern"
    given = [a.action for a in _advice(place, replay.id) if a.action is not None]
    assert given == recorded[: len(given)] and len(given) > 0  # fed by order
