"""A batch compares evaluative feedback with advice and with no feedback (issue 43): the
oracle judging runs to its end, its judgements are recorded and exported, its learner takes
its own actions, and oracle advice in the same study is another run."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from study.db.models import Advice, Feedback, Step
from tests.runs.batch.helpers import ADVICE, SCALE, Place, read_csv, sessions, study_id
from tests.runs.batch.helpers import in_process as run

pytestmark = pytest.mark.slow
PRETRAINING = 20  # SCALE's --pretraining-steps
STUDY = ["--study", "feedback kinds", "--agents", "1", *SCALE, "--workers", "1"]


def test_oracle_evaluation_beside_oracle_advice_and_no_feedback(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    evaluative = ["--feedback", "evaluative", "--feedback-weight", "0.5"]
    code, out = run(
        place, capsys, "batch", "--methods", "autonomous", "oracle", *evaluative, *STUDY
    )
    assert code == 0, out
    code, out = run(place, capsys, "batch", "--methods", "oracle", *STUDY)
    assert code == 0, out
    engine = place.engine()
    study = study_id(engine, "feedback kinds")
    autonomous, judged, advised = sessions(engine, study)
    assert {s.status for s in (autonomous, judged, advised)} == {"finished"}
    assert (judged.method, advised.method) == ("oracle", "oracle")
    assert (judged.spec.feedback, judged.spec.feedback_weight) == ("evaluative", 0.5)
    assert advised.spec.feedback == "advice" and autonomous.spec.feedback == "advice"

    with Session(engine) as db:
        ours = [autonomous.id, judged.id, advised.id]  # the place holds other tests' runs
        feedback = list(
            db.scalars(
                select(Feedback)
                .where(Feedback.session_id.in_(ours))
                .order_by(Feedback.session_id, Feedback.id)
            )
        )
        steps = {
            s.global_step: s for s in db.scalars(select(Step).where(Step.session_id == judged.id))
        }
        advice_of = set(db.scalars(select(Advice.session_id).where(Advice.session_id.in_(ours))))
    assert {f.session_id for f in feedback} == {judged.id} and advice_of == {advised.id}
    assert [f.feedback_index for f in feedback] == list(range(ADVICE))
    assert [f.global_step for f in feedback] == list(range(PRETRAINING - ADVICE + 1, 21))
    for f in feedback:
        step = steps[f.global_step]
        assert f.action == step.action and step.action_source == "random"
        assert step.advised_action is None and f.observation_hash == step.observation_hash
        assert f.judgement in (1.0, -1.0) and f.shaping == 0.5 * f.judgement
        assert f.evaluator == "oracle"
        # the task's correct action at the judged step: the one this oracle (no errors)
        # calls good, so good exactly where the action taken was it
        assert f.correct_action in range(4) and (f.judgement == 1.0) == (
            f.action == f.correct_action
        ), (f.global_step, f.action, f.correct_action, f.judgement)
    assert all(s.advised_action is None for s in steps.values())

    out_dir = place.data_dir / "feedback-export"
    code, out = run(place, capsys, "export", "--study", "feedback kinds", "--out", str(out_dir))
    assert code == 0, out
    rows = read_csv(out_dir / "feedback.csv")
    assert [(int(r["session_id"]), int(r["global_step"])) for r in rows] == [
        (f.session_id, f.global_step) for f in feedback
    ]
    assert [float(r["judgement"]) for r in rows] == [f.judgement for f in feedback]
    assert [int(r["correct_action"]) for r in rows] == [f.correct_action for f in feedback]
    assert {r["action_name"] for r in rows} <= {"grab", "move right", "move left", "drop"}
    kinds = {int(r["session_id"]): r["feedback"] for r in read_csv(out_dir / "sessions.csv")}
    assert kinds == {autonomous.id: "advice", judged.id: "evaluative", advised.id: "advice"}
    package = json.loads((out_dir / "datapackage.json").read_text())
    (resource,) = [r for r in package["resources"] if r["name"] == "feedback"]
    described = {f["name"]: f["type"] for f in resource["schema"]["fields"]}
    assert described["judgement"] == "number" and described["shaping"] == "number"
    assert described["correct_action"] == "integer"

    # The report compares oracle evaluation and oracle advice as two arms, from the
    # database and from the export alike, neither averaged into the other.
    from analysis.exported import read_export

    for source in ("database", "export"):
        report = place.data_dir / f"feedback-report-{source}"
        if source == "database":
            args = ["report", "--study", "feedback kinds", "--out", str(report)]
            code, out = run(place, capsys, *args)
            assert code == 0, out
            table = read_csv(report / "r_t_per_method.csv")
        else:
            exported = read_export(out_dir)
            table = [{"method": m} for m in sorted(set(exported.episodes["method"]))]
        methods = {r["method"] for r in table}
        assert methods == {"autonomous", "oracle", "oracle-evaluative"}, (source, methods)
    assert (
        "oracle evaluative feedback"
        in (place.data_dir / "feedback-report-database" / "report.md").read_text()
    )


def test_a_method_that_cannot_judge_is_refused(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["batch", "--study", "refused feedback", "--methods", "random", "--agents", "1"]
    code, out = run(place, capsys, *args, "--feedback", "evaluative", *SCALE)
    assert code == 2 and "method random cannot judge" in out, out


def test_the_two_learner_methods_are_two_arms(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same oracle ratings, used by shaping alone and by a rating model: two runs, two
    arms of the report, each run's method stored with it."""
    study = ["--study", "feedback methods", "--agents", "1", *SCALE, "--workers", "1"]
    evaluative = ["batch", "--methods", "oracle", "--feedback", "evaluative"]
    code, out = run(place, capsys, *evaluative, *study)
    assert code == 0, out
    code, out = run(place, capsys, *evaluative, "--feedback-method", "rating_model", *study)
    assert code == 0, out
    engine = place.engine()
    shaped, modelled = sessions(engine, study_id(engine, "feedback methods"))
    assert {shaped.status, modelled.status} == {"finished"}
    assert (shaped.spec.feedback_method, modelled.spec.feedback_method) == (
        "shaping",
        "rating_model",
    )
    with Session(engine) as db:
        judged = {
            s: [(f.global_step, f.judgement) for f in db.scalars(
                select(Feedback).where(Feedback.session_id == s).order_by(Feedback.id)
            )]
            for s in (shaped.id, modelled.id)
        }  # fmt: skip
    assert judged[shaped.id] == judged[modelled.id] and len(judged[shaped.id]) == ADVICE
    report = place.data_dir / "feedback-methods-report"
    code, out = run(place, capsys, "report", "--study", "feedback methods", "--out", str(report))
    assert code == 0, out
    methods = {r["method"] for r in read_csv(report / "r_t_per_method.csv")}
    assert methods == {"oracle-evaluative", "oracle-evaluative-rating_model"}
    assert "oracle evaluative feedback, rating model" in (report / "report.md").read_text()


def test_power_plans_from_evaluative_arms(place: Place, capsys: pytest.CaptureFixture[str]) -> None:
    """A pilot of judged and unadvised agents: the power analysis takes the judged arm as
    any other, by its arm's name."""
    study = ["--study", "judged pilot", "--agents", "2", *SCALE, "--workers", "1"]
    args = ["batch", "--methods", "autonomous", "oracle", "--feedback", "evaluative"]
    code, out = run(place, capsys, *args, *study)
    assert code == 0, out
    power = ["power", "--study", "judged pilot", "--draws", "100", "--max-n", "20"]
    code, out = run(place, capsys, *power, "--methods", "autonomous", "oracle-evaluative")
    assert code == 0, out
    assert "oracle evaluative feedback vs autonomous DeepRL" in out
    assert "pilot 2 + 2 agents" in out
    code, out = run(place, capsys, *power, "--baseline", "oracle-evaluative", "--json")
    assert code == 0, out
    (comparison,) = json.loads(out)["comparisons"]
    assert (comparison["method"], comparison["baseline"]) == ("autonomous", "oracle-evaluative")
