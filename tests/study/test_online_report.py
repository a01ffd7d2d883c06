"""An online study's report compares its conditions at the design's alpha, with the audit
told the condition is the manipulation, and never includes a researcher's preview."""

from __future__ import annotations

import random
from datetime import UTC, datetime
from pathlib import Path

import pytest

from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Advice, Episode, Status
from study.schemas.design import StudyDesign
from study.services import assignment, studies
from study.services.reports import build_report

RUN = {"method": "human", "config": {"pretraining_steps": 20, "advice_budget": 5, "batch_size": 8}}
EPISODES = 6


def _finish(db, session, rewards: random.Random) -> None:  # type: ignore[no-untyped-def]
    session.status = Status.finished.value
    for i in range(EPISODES):
        db.add(
            Episode(
                session_id=session.id, stage="train", episode=i + 1,
                collected_reward=rewards.uniform(0, 3), steps=50, placed_correct=1,
                misplaced=0, lost=0, success=False, terminated=True, truncated=False,
                advised_steps=0, epsilon=0.5, first_global_step=i * 50 + 1,
                last_global_step=(i + 1) * 50, wall_time=0.0,
            )
        )  # fmt: skip
    db.commit()


@pytest.mark.slow
def test_the_report_compares_the_conditions_without_previews(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'study.sqlite3'}")
    upgrade(engine)
    design = StudyDesign.model_validate(
        {
            "conditions": {
                "early": {"run": {**RUN, "strategy": "early"}, "target": 3},
                "alternating": {"run": {**RUN, "strategy": "alternating"}, "target": 3},
            },
            "alpha": 0.01,
        }
    )
    rewards = random.Random(5)
    with make_session_factory(engine)() as db:
        study = studies.create_study(db, "online-report", design=design)
        design = studies.design_of(study)
        assert design is not None
        tokens = [
            assignment.arrive(db, study, design, {"PROLIFIC_PID": f"R{i}"}, None).token
            for i in range(6)
        ]
        preview = assignment.arrive(db, study, design, {}, None, preview=True).token
        for token in [*tokens, preview]:
            session = assignment.session_for_token(db, str(token))
            assert session is not None
            _finish(db, session, rewards)
        preview_id = assignment.session_for_token(db, str(preview)).id  # type: ignore[union-attr]
        built = build_report(db, study.id, tmp_path / "report")
    analysis = built.result.analysis
    assert analysis is not None
    assert set(analysis.episodes["method"]) == {"early", "alternating"}
    assert preview_id not in set(analysis.episodes["session_id"])
    assert analysis.episodes["session_id"].nunique() == 6
    text = built.result.report.read_text()
    assert "α = 0.01" in text and "conditions are compared" in text
    assert "not comparable" not in text, "the strategy is the manipulation, not a mismatch"
    engine.dispose()


def test_the_participants_are_reported_before_any_learner_finishes(tmp_path: Path) -> None:
    """Three completed visits (two early, one alternating), one excluded, one declined,
    one timed out; no learner finished: the report is the participants' section, its
    first line says so, its flow counts are the sessions' outcomes."""
    engine = make_engine(f"sqlite:///{tmp_path / 'study.sqlite3'}")
    upgrade(engine)
    design = StudyDesign.model_validate(
        {
            "conditions": {
                "early": {"run": {**RUN, "strategy": "early"}, "target": 3},
                "alternating": {"run": {**RUN, "strategy": "alternating"}, "target": 3},
            }
        }
    )
    now = datetime(2026, 12, 6, tzinfo=UTC)
    with make_session_factory(engine)() as db:
        study = studies.create_study(db, "online-early", design=design)
        design = studies.design_of(study)
        assert design is not None
        visits = []
        for i in range(6):
            token = assignment.arrive(db, study, design, {"PROLIFIC_PID": f"P{i}"}, None).token
            session = assignment.session_for_token(db, str(token))
            assert session is not None
            visits.append(session)
        by_condition: dict[str, int] = {}
        for session, outcome in zip(
            sorted(visits, key=lambda s: (s.condition, s.id)),
            ["completed", "completed", "excluded", "completed", "declined", "timed_out"],
            strict=True,
        ):
            session.outcome = outcome
            session.status = Status.running.value  # the learner still trains
            if outcome != "declined":
                session.consented_at = now
            if outcome == "completed":
                by_condition[session.condition] = by_condition.get(session.condition, 0) + 1
                # action 0 each time; correct: 0, then 3 (accuracy 1/2), then unknown
                for k, (seconds, right) in enumerate(((1.0, 0), (3.0, 3), (2.0, None))):
                    db.add(
                        Advice(
                            session_id=session.id, advice_index=k, global_step=k + 1,
                            advisor="human", action=0, observation_png=b"",
                            response_time_s=seconds, decision_time_s=seconds,
                            requested_at=now, correct_action=right,
                        )
                    )  # fmt: skip
        db.commit()
        built = build_report(db, study.id, tmp_path / "report")
    assert built.result.analysis is None
    text = built.result.report.read_text()
    assert text.splitlines()[2].startswith("- Learners finished: 0 of the 3 completed visits")
    import pandas as pd

    flow = pd.read_csv(tmp_path / "report" / "participants_flow.csv").set_index("condition")
    assert flow["arrived"].sum() == 6 and flow["completed"].to_dict() == by_condition
    assert flow["declined"].sum() == 1 and flow["excluded"].sum() == 1
    assert flow["timed_out"].sum() == 1 and flow["consented"].sum() == 5
    people = pd.read_csv(tmp_path / "report" / "participants.csv")
    assert list(people["advice"]) == [3, 3, 3] and list(people["median_decision_s"]) == [2.0] * 3
    assert list(people["accuracy"]) == [0.5] * 3, "of the advice whose correct action is known"
    assert "Accuracy of advice is the share" in text
    engine.dispose()
