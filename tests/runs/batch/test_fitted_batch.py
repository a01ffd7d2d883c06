"""The whole path of a fitted advisor: an oracle pilot with an error rate and decision
times stands in for people, `ideeprl fit` recovers exactly what its advisor did from the
recorded rows, a `fitted` session (as `ideeprl batch --methods fitted` makes them) runs
advised by the model and logs its advice with decision times, and deleting a session the
model was fitted from deletes it and the runs it advised. Sessions run in this process by
the real worker (a batch's worker process would add its own start to the suite)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import delete, select, update
from sqlalchemy.orm import Session

from learner.run import RunSpec
from learner.seeding import reset_seeds
from runs.worker.worker import WorkerOptions, run_session
from study.db.migrate import upgrade
from study.db.models import Advice, Episode, FittedAdvisorModel, Step, StudySession
from study.services import storage
from study.services.errors import Invalid
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.runs.batch.helpers import SCALE, Place, sessions, study_id
from tests.runs.batch.helpers import in_process as run

pytestmark = pytest.mark.slow
BUDGET = 20  # all of SCALE's pretraining steps advised: more advice to fit
PILOT = ["--agents", "1", "--advice-budget", str(BUDGET), "--workers", "1"]
TINY = {"pretraining_steps": 20, "batch_size": 8, "memory_size": 200, "episodes": 2,
        "max_episode_steps": 15, "advice_budget": BUDGET}  # fmt: skip
"""SCALE's run, as a document."""


def _advice(engine: object, session_id: int) -> list[Advice]:
    with Session(engine) as db:  # type: ignore[arg-type]
        query = select(Advice).where(Advice.session_id == session_id)
        return list(db.scalars(query.order_by(Advice.advice_index)))


def test_a_model_fitted_to_an_oracle_pilot_advises_a_session_and_goes_with_its_data(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    upgrade(engine)
    with Session(engine) as db:  # the pilot: one oracle session, run by a real worker
        study = create_study(db, "fitted pilot").id
        spec = RunSpec.from_json({
            "method": "oracle", "error_rate": 0.3, "decision_time_median_s": 1.5, "config": TINY,
        })  # fmt: skip
        oracle_id = create_session(db, study, spec).id
    options = WorkerOptions(data_dir=place.data_dir)
    assert run_session(oracle_id, place.url, options) == "finished"
    (oracle,) = sessions(engine, study)
    advice = _advice(engine, oracle.id)
    assert len(advice) == BUDGET

    code, out = run(place, capsys, "fit", "--study", "fitted pilot", "--methods", "oracle",
                    "--json")  # fmt: skip
    assert code == 0, out
    fitted = json.loads(out)
    assert fitted["summary"]["advice"] == BUDGET and fitted["without_situation"] == 0
    # What the oracle drew, replayed from its seed: its wrong advice and its times. The
    # fit knew neither; it found them by replaying the recorded episodes.
    draws = np.random.default_rng(oracle.seed)
    wrong = 0
    for _ in range(BUDGET):
        wrong += draws.random() < 0.3
        draws.integers(3)
    times = np.random.default_rng(np.random.SeedSequence(oracle.seed).spawn(1)[0])
    drawn = [1.5 * math.exp(0.5 * times.standard_normal()) for _ in range(BUDGET)]
    assert [a.decision_time_s for a in advice] == pytest.approx(drawn)
    with Session(engine) as db:
        row = db.get(FittedAdvisorModel, fitted["id"])
        assert row is not None and row.session_ids == [oracle.id]
        assert row.model["overall"] == {"advice": BUDGET, "wrong": wrong}
        assert row.model["decision_time_median_s"] == pytest.approx(
            math.exp(float(np.mean(np.log(drawn))))
        )
    path = Path(fitted["path"])
    assert path.is_file() and path.is_relative_to(place.data_dir.resolve())

    with Session(engine) as db:  # as if the pilot had left during its last advised episode
        episodes = list(db.scalars(select(Episode).where(Episode.session_id == oracle.id)
                                   .order_by(Episode.id)))  # fmt: skip
        assert reset_seeds(oracle.seed, len(episodes)) == [e.reset_seed for e in episodes]
        (left_in,) = [e for e in episodes if e.first_global_step <= advice[-1].global_step
                      <= e.last_global_step]  # fmt: skip
        db.execute(delete(Episode).where(Episode.session_id == oracle.id,
                                         Episode.id >= left_in.id))  # fmt: skip
        db.execute(delete(Step).where(Step.session_id == oracle.id,
                                      Step.global_step > advice[-1].global_step))  # fmt: skip
        db.commit()
    code, out = run(place, capsys, "fit", "--study", "fitted pilot", "--methods", "oracle",
                    "--json")  # fmt: skip
    assert code == 0, out
    again = json.loads(out)  # its unrecorded episode replayed from the run's next reset seed
    assert again["without_situation"] == 0
    assert again["model"]["overall"] == {"advice": BUDGET, "wrong": wrong}

    advised = ["batch", "--study", "fitted pilot", "--methods", "fitted", *SCALE, *PILOT]
    code, out = run(place, capsys, *advised, "--fitted-model", str(path), "--dry-run")
    assert code == 0 and "fitted #1" in out and "new" in out, out  # the batch takes it
    stored = f"fitted:{fitted['id']}"  # ... or the stored model by its id, as the API does
    by_id = ["batch", "--study", "fitted by id", "--methods", "fitted", *SCALE, *PILOT]
    code, out = run(place, capsys, *by_id, "--fitted-model", stored)
    assert code == 0, out
    (batch_run,) = sessions(engine, study_id(engine, "fitted by id"))
    assert batch_run.status == "finished" and batch_run.spec.fitted_model == str(path)
    code, out = run(place, capsys, *by_id, "--fitted-model", "fitted:999999", "--dry-run")
    assert code == 2 and "no stored model" in out, out
    with Session(engine) as db:  # ... and so does a session, run here by a real worker
        spec = RunSpec.from_json({"method": "fitted", "fitted_model": str(path), "config": TINY})
        by_model = create_session(db, study, spec).id
    assert run_session(by_model, place.url, options) == "finished"
    (run_by_model,) = [s for s in sessions(engine, study) if s.method == "fitted"]
    assert run_by_model.spec.fitted_model == str(path)
    logged = _advice(engine, run_by_model.id)
    assert len(logged) == BUDGET and {a.advisor for a in logged} == {"fitted"}
    assert all(a.decision_time_s is not None and a.decision_time_s > 0 for a in logged)

    with Session(engine) as db:  # a stored model by its id, through the server's rule
        spec = RunSpec.from_json({"method": "fitted", "fitted_model": f"fitted:{fitted['id']}"})
        made = create_session(db, study, spec, data_dir=place.data_dir)
        assert made.spec.fitted_model == str(path)
        with pytest.raises(Invalid, match="no stored model"):
            create_session(
                db, study, spec.replace(fitted_model="fitted:999999"), data_dir=place.data_dir
            )
        outside = spec.replace(fitted_model="/etc/passwd")
        with pytest.raises(Invalid, match="under the server's data folder"):
            create_session(db, study, outside, data_dir=place.data_dir)
        storage.delete_session(db, place.data_dir, made.id, live_here=False)

    fit = ["fit", "--study", "fitted pilot", "--methods", "oracle", "--json"]
    with Session(engine) as db:  # a session still running counts once its budget is spent
        db.execute(update(StudySession).where(StudySession.id == oracle.id)
                   .values(status="running"))  # fmt: skip
        db.commit()
    code, out = run(place, capsys, *fit, "--sessions", str(oracle.id))
    assert code == 0 and json.loads(out)["summary"]["advice"] == BUDGET, out
    code, out = run(place, capsys, *fit, "--sessions", str(oracle.id + 1000))
    assert code == 1 and "no oracle session with advice to fit" in out, out
    with Session(engine) as db:  # ... never while its advisor may give more
        db.execute(delete(Advice).where(Advice.id == advice[-1].id))
        db.commit()
    code, out = run(place, capsys, *fit)
    assert code == 1 and "no oracle session with advice to fit" in out, out

    with Session(engine) as db:  # the pilot's data goes, the models made from it, and
        # the runs they advised (the pilot's advice lives on in them as in the model)
        db.execute(update(StudySession).where(StudySession.id == oracle.id)
                   .values(status="finished"))  # fmt: skip
        db.commit()
        storage.delete_session(db, place.data_dir, oracle.id, live_here=False)
        left = db.scalars(select(FittedAdvisorModel).where(FittedAdvisorModel.study_id == study))
        assert list(left) == []
        assert db.get(StudySession, run_by_model.id) is None
        assert db.get(StudySession, batch_run.id) is None, "in another study too"
    assert not path.exists()
    assert not storage.session_dir(place.data_dir, run_by_model.id).exists()


def test_fit_says_what_is_missing(place: Place, capsys: pytest.CaptureFixture[str]) -> None:
    upgrade(place.engine())
    with Session(place.engine()) as db:
        create_study(db, "unadvised")
    code, out = run(place, capsys, "fit", "--study", "unadvised")
    assert code == 1 and "no human session with advice to fit" in out, out
    code, out = run(place, capsys, "fit", "--study", "unadvised", "--methods", "sb3-dqn")
    assert code == 2 and "methods must be among the advised" in out, out
    code, out = run(place, capsys, "batch", "--study", "unadvised", "--methods", "fitted",
                    "--fitted-model", str(place.data_dir / "none.json"), *SCALE)  # fmt: skip
    assert code == 2 and "no fitted model at" in out, out
