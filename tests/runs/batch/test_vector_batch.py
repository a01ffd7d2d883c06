"""A vector task (CartPole-v1, defined in the tests) through `ideeprl batch`: its runs
train the dense network from the task's preset in worker processes, and are stored and
reported like any task's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from sqlalchemy import select
from sqlalchemy.orm import Session

from learner.records import observation_hash
from study.db.models import Advice, Step
from study.services.observations import decode_png, observation_of
from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, study_id

pytestmark = pytest.mark.slow
CARTPOLE = "tests.tasks.cartpole:cartpole_task"


def test_a_vector_tasks_batch_runs_and_reports(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    batch = [
        "batch", "--study", "cartpole", "--task", CARTPOLE, "--methods", "autonomous",
        "random", "--agents", "2", "--workers", "1", "--report", str(tmp_path / "report"),
        *SCALE,
    ]  # fmt: skip
    code, output = in_process(place, capsys, *batch)
    assert code == 0, output
    engine = place.engine()
    rows = sessions(engine, study_id(engine, "cartpole"))
    assert len(rows) == 4 and all(s.status == "finished" for s in rows), output
    assert {s.spec.preset for s in rows} == {"modern"} and {s.spec.task for s in rows} == {CARTPOLE}
    methods = pd.read_csv(tmp_path / "report" / "r_t_per_method.csv")
    assert methods["method"].tolist() == ["autonomous", "random"]
    assert methods["agents"].tolist() == [2, 2]

    # Each advice holds the vector the learner saw (its step's hash) and the cart's frame.
    advised = [s.id for s in rows if s.method == "random"]
    with Session(engine) as db:
        advice = list(db.scalars(select(Advice).where(Advice.session_id.in_(advised))))
        hashes = {
            (t.session_id, t.global_step): t.observation_hash
            for t in db.scalars(select(Step).where(Step.session_id.in_(advised)))
        }
    assert len(advice) == 2 * 8
    for a in advice:
        vector = observation_of(a.observation_png)
        assert vector.shape == (4,) and vector.dtype == np.float32 and np.abs(vector).max() > 0
        assert observation_hash(vector) == hashes[(a.session_id, a.global_step)]
        frame = decode_png(a.observation_png)
        assert frame.shape == (400, 600, 3) and len(np.unique(frame.reshape(-1, 3), axis=0)) > 2


def test_the_sb3_baseline_runs_a_vector_task_through_the_batch_with_its_mlp_policy(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    pytest.importorskip("stable_baselines3")
    batch = [
        "batch", "--study", "cartpole sb3", "--task", CARTPOLE, "--methods", "sb3-dqn",
        "--agents", "1", "--workers", "1", "--report", str(tmp_path / "report"), *SCALE,
    ]  # fmt: skip
    code, output = in_process(place, capsys, *batch)
    assert code == 0, output
    engine = place.engine()
    (run,) = sessions(engine, study_id(engine, "cartpole sb3"))
    assert (run.status, run.method, run.spec.task) == ("finished", "sb3-dqn", CARTPOLE), output
    final = torch.load(run.checkpoint_path or "", map_location="cpu", weights_only=True)
    assert final["hyperparameters"]["sb3_policy"] == "MlpPolicy"
    assert final["policy"]["q_net.q_net.0.weight"].shape[1] == 4  # the cart's four numbers
    with Session(engine) as db:
        steps = list(db.scalars(select(Step).where(Step.session_id == run.id)))
    assert {t.action_source for t in steps if t.stage == "pretrain"} == {"random"}
    assert all(t.loss is not None for t in steps if t.stage == "train")
    settings = pd.read_csv(tmp_path / "report" / "settings_per_method.csv")
    (learner,) = settings["learner"].tolist()
    assert "policy=CnnPolicy (MlpPolicy on vectors)" in learner
