"""The participants' section is the same whether the report is built from the database
(`ideeprl report`, the dashboard) or from the study's export (`python -m analysis
EXPORT OUT`): while no learner has finished, and once some have."""

from __future__ import annotations

import json
import random
from datetime import UTC, datetime
from pathlib import Path

import pandas as pd
import pytest
from sqlalchemy.orm import Session

from analysis.__main__ import main as analyse
from analysis.comparable_report import COMPARABLE_FILES
from analysis.human_report import TABLE_FILES
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import (
    Advice,
    CheckAttempt,
    Episode,
    QuestionnaireAnswer,
    Status,
    StudySession,
)
from study.schemas.design import StudyDesign
from study.schemas.instruments import NASA_TLX
from study.services import assignment, studies
from study.services.export import export_study
from study.services.reports import build_report

RUN = {"method": "human", "config": {"pretraining_steps": 20, "advice_budget": 5, "batch_size": 8}}
NOW = datetime(2026, 12, 6, tzinfo=UTC)
OUTCOMES = {
    "alternating": ["completed", "completed", "completed", "declined", "timed_out"],
    "early": ["completed", "completed", "completed", "excluded", "completed"],
}


def _visit(db: Session, session: StudySession, outcome: str, rng: random.Random) -> None:
    """What a participant did: consent, the check (a retry for some), advice with decision
    times (one request left unanswered), the questionnaire."""
    session.outcome = outcome
    session.status = Status.running.value
    if outcome == "declined":
        return
    session.consented_at = NOW
    tries = [False, False] if outcome == "excluded" else rng.choice([[True], [False, True]])
    for attempt, correct in enumerate(tries, start=1):
        db.add(
            CheckAttempt(
                session_id=session.id, attempt=attempt,
                answers={"q1": "left" if correct else "right"}, expected={"q1": "left"},
                questions={"q1": "Where does a red cube go?"},
                correct=correct, answered_at=NOW,
            )
        )  # fmt: skip
    if outcome != "completed":
        return
    for k in range(rng.randint(3, 6)):
        answered = k != 2
        db.add(
            Advice(
                session_id=session.id, advice_index=k, global_step=10 * k + 1, advisor="human",
                action=rng.randint(0, 3) if answered else None, observation_png=b"",
                response_time_s=1.0, decision_time_s=rng.uniform(0.5, 6.0) if answered else None,
                requested_at=NOW, correct_action=rng.choice([0, 1, 2, 3, None]),
            )
        )  # fmt: skip
    for subscale in NASA_TLX:
        value = float(rng.randrange(0, 101, 5))
        db.add(_answer(session.id, "nasa_tlx", subscale.id, value))
    db.add(_answer(session.id, "custom", "fun", float(rng.randint(1, 5))))


def _answer(session_id: int, instrument: str, item: str, value: float) -> QuestionnaireAnswer:
    return QuestionnaireAnswer(
        session_id=session_id, instrument=instrument, item=item, text=item,
        value_number=value, value_text=None, answered_at=NOW,
    )  # fmt: skip


def _finish(db: Session, session: StudySession, rng: random.Random) -> None:
    session.status = Status.finished.value
    for i in range(4):
        db.add(
            Episode(
                session_id=session.id, stage="train", episode=i + 1,
                collected_reward=rng.uniform(0, 3), steps=50, placed_correct=1, misplaced=0,
                lost=0, success=False, terminated=True, truncated=False, advised_steps=0,
                epsilon=0.5, first_global_step=i * 50 + 1, last_global_step=(i + 1) * 50,
                wall_time=0.0,
            )
        )  # fmt: skip


def _primary(report: Path) -> str:
    text = (report / "report.md").read_text()
    return text[text.index("## Primary test") :].split("\n## ")[0]


def _same_tables(database: Path, exported: Path, learning: bool = False) -> None:
    assert _primary(database) == _primary(exported)
    assert "power" in _primary(exported) and "statistic" in _primary(exported)
    names = [*TABLE_FILES.values()]
    if learning:
        names += [COMPARABLE_FILES["scores"], COMPARABLE_FILES["timing"]]
    for name in names:
        a, b = pd.read_csv(database / name), pd.read_csv(exported / name)
        pd.testing.assert_frame_equal(a, b, check_dtype=False, obj=name)


@pytest.mark.slow
def test_the_export_gives_the_databases_participants_section(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'study.sqlite3'}")
    upgrade(engine)
    design = StudyDesign.model_validate(
        {
            "conditions": {
                name: {"run": {**RUN, "strategy": name}, "target": 5} for name in OUTCOMES
            },
            "alpha": 0.1,
            "capacity": 10,
            "primary": {"measure": "nasa_tlx", "test": "welch", "effect": 10},
        }
    )
    rng = random.Random(44)
    with make_session_factory(engine)() as db:
        study = studies.create_study(db, "both-ways", design=design)
        design = studies.design_of(study)
        assert design is not None
        arrived = []
        for i in range(10):
            token = assignment.arrive(db, study, design, {"PROLIFIC_PID": f"B{i}"}, None).token
            session = assignment.session_for_token(db, str(token))
            assert session is not None
            arrived.append(session)
        by_condition = {name: [s for s in arrived if s.condition == name] for name in OUTCOMES}
        for name, outcomes in OUTCOMES.items():
            for session, outcome in zip(by_condition[name], outcomes, strict=True):
                _visit(db, session, outcome, rng)
        db.commit()

        build_report(db, study.id, tmp_path / "database-0")
        export_study(db, study.id, tmp_path / "export-0")
        assert analyse([str(tmp_path / "export-0"), str(tmp_path / "exported-0")]) == 0
        _same_tables(tmp_path / "database-0", tmp_path / "exported-0")
        first = (tmp_path / "exported-0" / "report.md").read_text().splitlines()[2]
        assert first.startswith("- Learners finished: 0 of the 7 completed visits")

        for name in OUTCOMES:  # two learners of each condition finish
            for session in by_condition[name][:2]:
                _finish(db, session, rng)
        db.commit()
        build_report(db, study.id, tmp_path / "database-4")
        export_study(db, study.id, tmp_path / "export-4")
        export_study(db, study.id, tmp_path / "parquet-4", fmt="parquet")
    engine.dispose()
    assert analyse([str(tmp_path / "export-4"), str(tmp_path / "exported-4")]) == 0
    _same_tables(tmp_path / "database-4", tmp_path / "exported-4", learning=True)
    assert analyse([str(tmp_path / "parquet-4"), str(tmp_path / "from-parquet")]) == 0
    _same_tables(tmp_path / "database-4", tmp_path / "from-parquet", learning=True)
    text = (tmp_path / "exported-4" / "report.md").read_text()
    assert "Learners finished: 4 of the 7 completed visits" in text
    assert "## The participants" in text and "## Learning outcomes that compare like" in text
    tests = pd.read_csv(tmp_path / "exported-4" / TABLE_FILES["tests"])
    assert tests["p"].notna().sum() >= 5, "numbers to compare, not only 'no test'"
    people = pd.read_csv(tmp_path / "exported-4" / TABLE_FILES["participants"])
    assert len(people) == 7 and people["scale_nasa_tlx"].notna().all()
    assert people["accuracy"].notna().any()

    _without_correct_action(tmp_path / "export-4")  # as an export made before it was stored
    assert analyse([str(tmp_path / "export-4"), str(tmp_path / "older")]) == 0
    older = pd.read_csv(tmp_path / "older" / TABLE_FILES["participants"])
    assert older["accuracy"].isna().all()
    pd.testing.assert_frame_equal(older.drop(columns="accuracy"), people.drop(columns="accuracy"))
    assert "no correct action" in (tmp_path / "older" / "report.md").read_text()


def _without_correct_action(export: Path) -> None:
    advice = pd.read_csv(export / "advice.csv", dtype=str, keep_default_na=False)
    advice.drop(columns="correct_action").to_csv(export / "advice.csv", index=False)
    package = json.loads((export / "datapackage.json").read_text())
    for resource in package["resources"]:
        fields = resource["schema"]["fields"]
        resource["schema"]["fields"] = [f for f in fields if f["name"] != "correct_action"]
    (export / "datapackage.json").write_text(json.dumps(package))
