"""The whole path of a fitted evaluator: an oracle pilot judging with an error rate and
decision times stands in for people rating, `ideeprl fit` recovers from the recorded
feedback rows exactly how often its ratings said what the correct action says of the move
(by whether the move was right) and its times, `ideeprl batch --methods fitted --feedback
evaluative` runs judged by the model, and `ideeprl power` plans from that arm."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from study.db.models import Feedback
from tests.runs.batch.helpers import ADVICE, SCALE, Place, sessions, study_id
from tests.runs.batch.helpers import in_process as run

pytestmark = pytest.mark.slow
BUDGET = 20  # all of SCALE's pretraining steps judged: more ratings to fit
ERROR_RATE, MEDIAN_S = 0.3, 1.5
EVALUATIVE = ["--feedback", "evaluative", "--workers", "1", *SCALE]


def _feedback(place: Place, session_id: int) -> list[Feedback]:
    with Session(place.engine()) as db:
        query = select(Feedback).where(Feedback.session_id == session_id)
        return list(db.scalars(query.order_by(Feedback.feedback_index)))


def test_an_evaluator_fitted_to_a_pilot_judges_runs_and_plans_a_study(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    pilot = ["batch", "--study", "rated pilot", "--methods", "oracle", "--agents", "1"]
    timed = ["--error-rate", str(ERROR_RATE), "--decision-time-median-s", str(MEDIAN_S)]
    code, out = run(place, capsys, *pilot, *timed, *EVALUATIVE, "--advice-budget", str(BUDGET))
    assert code == 0, out
    engine = place.engine()
    (oracle,) = sessions(engine, study_id(engine, "rated pilot"))
    rows = _feedback(place, oracle.id)
    assert oracle.status == "finished" and len(rows) == BUDGET

    code, out = run(place, capsys, "fit", "--study", "rated pilot", "--methods", "oracle",
                    "--json")  # fmt: skip
    assert code == 0, out
    fitted = json.loads(out)
    model = fitted["model"]
    assert model["kind"] == "evaluative" and fitted["without_situation"] == 0
    assert (model["turns"], model["answered"]) == (BUDGET, BUDGET)
    # Which judgements the oracle turned into their opposite, drawn again from its seed
    # (`AdvisorEvaluator`'s own stream): the fit knew none of them; it replayed the
    # recorded episodes to know whether each move rated was the correct action.
    flips = np.random.default_rng(np.random.SeedSequence(oracle.seed).spawn(2)[1])
    flipped = [bool(flips.random() < ERROR_RATE) for _ in range(BUDGET)]
    right = [(r.judgement == 1.0) != f for r, f in zip(rows, flipped, strict=True)]
    expected = {
        move: {"ratings": sum(r == want for r in right),
               "wrong": sum(r == want and f for r, f in zip(right, flipped, strict=True))}
        for move, want in (("right", True), ("wrong", False))
    }  # fmt: skip
    assert model["by_move"] == {m: c for m, c in expected.items() if c["ratings"]}
    assert model["good"] == sum(r.judgement == 1.0 for r in rows)
    assert model["silent_shares"] == [0.0]
    times = [r.decision_time_s for r in rows]
    assert all(t is not None and t > 0 for t in times)
    assert model["decision_time_median_s"] == pytest.approx(
        math.exp(float(np.mean(np.log(times))))  # type: ignore[arg-type]
    )
    code, out = run(place, capsys, "fit", "--study", "rated pilot", "--methods", "oracle")
    assert code == 0 and "fitted evaluator" in out and "--feedback evaluative" in out, out
    path = Path(fitted["path"])

    judged = ["batch", "--study", "judged by fitted", "--agents", "2"]
    code, out = run(place, capsys, *judged, "--methods", "fitted", "--fitted-model", str(path))
    assert code == 2 and "fitted to ratings" in out, out  # advice runs cannot take it
    code, out = run(place, capsys, *judged, "--methods", "autonomous", "fitted",
                    "--fitted-model", str(path), *EVALUATIVE)  # fmt: skip
    assert code == 0, out
    runs = sessions(engine, study_id(engine, "judged by fitted"))
    assert sorted(s.method for s in runs) == ["autonomous"] * 2 + ["fitted"] * 2
    assert {s.status for s in runs} == {"finished"}
    for s in runs:
        given = _feedback(place, s.id)
        if s.method == "autonomous":
            assert given == []
            continue
        assert s.spec.feedback == "evaluative" and s.spec.fitted_model == str(path)
        assert len(given) == ADVICE and {f.evaluator for f in given} == {"fitted"}
        assert all(f.judgement in (1.0, -1.0) for f in given)  # its people answered all
        assert all(f.decision_time_s is not None and f.decision_time_s > 0 for f in given)

    power = ["power", "--study", "judged by fitted", "--draws", "100", "--max-n", "20"]
    code, out = run(place, capsys, *power, "--methods", "autonomous", "fitted-evaluative")
    assert code == 0, out
    assert "pilot 2 + 2 agents" in out and "fitted evaluative feedback vs autonomous" in out, out
