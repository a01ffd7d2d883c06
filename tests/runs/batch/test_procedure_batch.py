"""The procedure control in a batch: each control runs once its advised run has finished,
with that run's schedule and settings, and the report pairs the two."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from study.db.models import Step
from tests.runs.batch.helpers import SCALE, Place, in_process, read_csv, sessions, study_id

pytestmark = pytest.mark.slow


def _schedule(place: Place, session_id: int) -> tuple[list[int], list[int], list[float]]:
    with Session(place.engine()) as db:
        rows = db.execute(
            select(Step.global_step, Step.stage, Step.action_source, Step.loss, Step.epsilon)
            .where(Step.session_id == session_id)
            .order_by(Step.global_step)
        ).all()
    advised = [r.global_step for r in rows if r.action_source == "advisor"]
    fits = [r.global_step for r in rows if r.stage == "pretrain" and r.loss is not None]
    return advised, fits, [r.epsilon for r in rows]


def test_each_control_follows_its_advised_runs_schedule(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    args = [
        "batch", "--study", "controls", "--methods", "oracle", "procedure", "--agents", "2",
        "--control-of", "oracle", "--set", "update_during_advice=true",
        "--set", "update_on_final_step=false",
    ]  # fmt: skip
    code, out = in_process(place, capsys, *args, *SCALE)
    assert code == 0, out
    study = study_id(place.engine(), "controls")
    runs = sessions(place.engine(), study)
    assert sorted(s.method for s in runs) == ["oracle", "oracle", "procedure", "procedure"]
    for control in (s for s in runs if s.method == "procedure"):
        (advised,) = [s for s in runs if s.method == "oracle" and s.seed == control.seed]
        assert control.status == "finished" and control.started_at >= advised.finished_at
        assert Path(control.spec.schedule or "").name == f"session-{advised.id}.json"
        mine, theirs = _schedule(place, control.id), _schedule(place, advised.id)
        common = min(len(mine[2]), len(theirs[2]))
        assert mine[0] == theirs[0] and mine[1] == theirs[1] and theirs[1]
        assert mine[2][:common] == theirs[2][:common]
    # run again: nothing to do
    code, _ = in_process(place, capsys, *args, *SCALE)
    assert code == 0 and len(sessions(place.engine(), study)) == 4

    out_dir = tmp_path / "report"
    code, printed = in_process(
        place, capsys, "report", "--study", str(study), "--out", str(out_dir),
        "--primary", "paired",
    )  # fmt: skip
    assert code == 0, printed
    (row,) = read_csv(out_dir / "primary_and_secondary_tests.csv")
    assert (row["method"], row["baseline"], row["primary"]) == ("oracle", "procedure", "paired")


def test_a_control_needs_its_advised_method_in_the_batch(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out = in_process(
        place, capsys, "batch", "--study", "lonely", "--methods", "procedure", *SCALE
    )
    assert code == 2 and "--control-of agent is not among --methods" in out


def test_the_control_of_a_judged_run_is_judged_at_its_judged_steps(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    """Evaluative feedback: the control gets an uninformed judgement at each step its oracle
    run judged, fits where it fitted and follows its epsilon."""
    from study.db.models import Feedback

    args = [
        "batch", "--study", "judged controls", "--methods", "oracle", "procedure",
        "--agents", "1", "--control-of", "oracle", "--feedback", "evaluative",
        "--set", "update_during_advice=true",
    ]  # fmt: skip
    code, out = in_process(place, capsys, *args, *SCALE)
    assert code == 0, out
    runs = sessions(place.engine(), study_id(place.engine(), "judged controls"))
    (judged,) = [s for s in runs if s.method == "oracle"]
    (control,) = [s for s in runs if s.method == "procedure"]
    assert control.status == "finished" and control.spec.feedback == "evaluative"

    def ratings(session_id: int) -> dict[int, float | None]:
        with Session(place.engine()) as db:
            query = select(Feedback).where(Feedback.session_id == session_id)
            return {f.global_step: f.judgement for f in db.scalars(query)}

    mine, theirs = ratings(control.id), ratings(judged.id)
    assert sorted(mine) == sorted(theirs) and theirs
    assert set(mine.values()) <= {1.0, -1.0}
    schedule_mine, schedule_theirs = _schedule(place, control.id), _schedule(place, judged.id)
    assert schedule_mine[0] == schedule_theirs[0] == []  # no advice: its own actions
    assert schedule_mine[1] == schedule_theirs[1] and schedule_theirs[1]  # judged steps fit
    common = min(len(schedule_mine[2]), len(schedule_theirs[2]))
    assert schedule_mine[2][:common] == schedule_theirs[2][:common]
