"""An online study whose conditions stand for ways people teach (advice, evaluative
ratings), from its export: the report knows its sessions as human ones whatever the
conditions are called, and the participants' section counts the ratings of the `feedback`
table, checked against the same worked out by hand."""

from __future__ import annotations

import csv
import json
import shutil
from datetime import UTC, datetime
from pathlib import Path

import pandas as pd
import pytest

from analysis.__main__ import main
from analysis.human import participants
from learner.run import RunSpec
from study.db.engine import make_session_factory
from study.services.episodes import load_visits
from study.services.feedback import FeedbackGiven, write_feedback
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.analysis.stored import migrated_folder
from tests.analysis.test_exported import OLD_EXPORT

CONDITIONS = {1: "rating", 2: "advising", 3: "rating", 4: "advising"}
"""The fixture's sessions as the study's conditions: its oracle sessions (8 advice each)
advised by participants, its autonomous ones rated by participants."""
RATINGS = [
    # session, index, judgement, decision time: 1 rates twice, and once does not answer
    (1, 0, 1.0, 2.0), (1, 1, -1.0, 4.0), (1, 2, None, None),
    # 3 rates three times
    (3, 0, 1.0, 1.0), (3, 1, 1.0, 1.0), (3, 2, -1.0, 7.0),
]  # fmt: skip
CORRECT = [1, 1, 2, 2, 1, 0]
"""The task's correct action beside each of `RATINGS` (every rated action is 1). Worked
out by hand: 1 says good of the correct action (right), bad of it (wrong), and gives no
answer (not scored): 1 of 2; 3 says good of another (wrong), good of the correct one
(right), bad of another (right): 2 of 3."""
ACCURACY = {1: 1 / 2, 3: 2 / 3}


def _write(path: Path, rows: list[dict[str, object]]) -> None:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _read(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def _online_export(folder: Path, correct: bool = False) -> None:
    """The fixture's export as a small online study's: a design with the two conditions,
    every visit completed, the advice a participant's, and a `feedback.csv` of ratings as
    the server exports it: with the task's correct action beside each rating (`CORRECT`),
    or without that column, as an export written before it was recorded."""
    shutil.copytree(OLD_EXPORT, folder)
    sessions = _read(folder / "sessions.csv")
    for row in sessions:
        row["condition"] = CONDITIONS[int(row["session_id"])]
        row["outcome"] = "completed"
        row["consented_at"] = row["started_at"]
    _write(folder / "sessions.csv", sessions)  # type: ignore[arg-type]
    advice = _read(folder / "advice.csv")
    for row in advice:
        row["advisor"] = "human"
    _write(folder / "advice.csv", advice)  # type: ignore[arg-type]
    _write(
        folder / "feedback.csv",
        [
            {"session_id": s, "feedback_index": i, "global_step": 20 + i, "evaluator": "human",
             "action": 1, "judgement": "" if j is None else j, "shaping": 0.0,
             "greedy_action": 1, "observation_hash": "0" * 16, "response_time_s": 1.0,
             "decision_time_s": "" if t is None else t, "requested_at": "",
             "answered_at": "", **({"correct_action": c} if correct else {})}
            for (s, i, j, t), c in zip(RATINGS, CORRECT, strict=True)
        ],
    )  # fmt: skip
    study = json.loads((folder / "study.json").read_text())
    study["design"] = {
        "alpha": 0.05,
        "conditions": {name: {"run": {"method": "human"}} for name in ("advising", "rating")},
    }
    (folder / "study.json").write_text(json.dumps(study))


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("human-export")
    _online_export(root / "export")
    assert main([str(root / "export"), str(root / "report")]) == 0
    return root / "report"


def test_the_ratings_accuracy_against_their_correct_actions_by_hand(tmp_path: Path) -> None:
    _online_export(tmp_path / "export", correct=True)
    assert main([str(tmp_path / "export"), str(tmp_path / "report")]) == 0
    people = pd.read_csv(tmp_path / "report" / "participants.csv").set_index("session_id")
    assert people.loc[[1, 3], "accuracy"].to_dict() == pytest.approx(ACCURACY)
    assert people.loc[[2, 4], "accuracy"].isna().all(), "this export's advice has none"
    text = (tmp_path / "report" / "report.md").read_text()
    assert "Accuracy of ratings is the share" in text
    assert "No accuracy for ratings" not in text
    # rating: the mean of the participants' accuracies, (1/2 + 2/3) / 2 = 0.58
    assert "| rating | 2 | ratings | 2.50 | 0.58 | 2.00 |" in text
    tests = pd.read_csv(tmp_path / "report" / "participants_tests.csv").set_index("measure")
    assert tests.loc["accuracy", ["n_a", "n_b"]].tolist() == [0, 2]


def test_conditions_of_people_advising_are_human_sessions_whatever_their_names(
    report: Path,
) -> None:
    text = (report / "report.md").read_text()
    assert "no human-IDeepRL sessions" not in text
    assert "None of the paper's methods" not in text
    assert "Figure 6 shows the individual advising agents, learners a participant advised" in text
    assert "Participants advised the learners of advising, rating" in text


def test_the_participants_section_counts_the_ratings_by_hand(report: Path) -> None:
    people = pd.read_csv(report / "participants.csv").set_index("session_id")
    assert people["gave"].to_dict() == {1: "ratings", 2: "advice", 3: "ratings", 4: "advice"}
    # 1: two answers (one unanswered), median of 2.0 and 4.0; 3: three, median of 1, 1, 7
    assert people["advice"].to_dict() == {1: 2, 2: 8, 3: 3, 4: 8}
    assert people.loc[[1, 3], "median_decision_s"].tolist() == [3.0, 1.0]
    assert people["accuracy"].isna().all(), "no correct action in this export"
    text = (report / "report.md").read_text()
    assert "No accuracy for ratings: the feedback table records no correct action" in text
    # rating: 2.5 ratings a participant; the median of the medians 3.0 and 1.0
    assert "| rating | 2 | ratings | 2.50 | – | 2.00 |" in text
    tests = pd.read_csv(report / "participants_tests.csv").set_index("measure")
    assert tests.loc["advice or ratings given", ["n_a", "n_b"]].tolist() == [2, 2]


def test_the_databases_ratings_read_as_the_exports(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The dashboard's report reads the visits from the database: the same ratings give the
    same counts and decision times as from the export."""
    _, engine = migrated_folder(tmp_path, monkeypatch)
    now = datetime.now(UTC)
    with make_session_factory(engine)() as db:
        study = create_study(db, "ratings")
        made = []
        for seed in (1, 3):
            session = create_session(db, study.id, RunSpec(method="autonomous", seed=seed))
            session.condition, session.outcome, session.consented_at = "rating", "completed", now
            made.append(session)
        ids = {1: made[0].id, 3: made[1].id}
        write_feedback(
            db,
            [
                FeedbackGiven(ids[s], i, 20 + i, "human", 1, j, 0.0, 1, "0" * 16, 1.0, t, now, now)
                for s, i, j, t in RATINGS
            ],
        )
        db.commit()
        people = participants(load_visits(db, made)).set_index("session_id")
    engine.dispose()
    assert people.loc[[ids[1], ids[3]], "advice"].tolist() == [2, 3]
    assert people.loc[[ids[1], ids[3]], "median_decision_s"].tolist() == [3.0, 1.0]
    assert set(people["gave"]) == {"ratings"} and people["accuracy"].isna().all()


def test_the_databases_correct_actions_give_the_ratings_accuracy(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ratings stored with the task's correct action: the dashboard's report scores them
    as the export's are scored by hand."""
    _, engine = migrated_folder(tmp_path, monkeypatch)
    now = datetime.now(UTC)
    with make_session_factory(engine)() as db:
        study = create_study(db, "ratings with their correct actions")
        made = []
        for seed in (1, 3):
            session = create_session(db, study.id, RunSpec(method="autonomous", seed=seed))
            session.condition, session.outcome, session.consented_at = "rating", "completed", now
            made.append(session)
        ids = {1: made[0].id, 3: made[1].id}
        write_feedback(
            db,
            [
                FeedbackGiven(ids[s], i, 20 + i, "human", 1, j, 0.0, 1, "0" * 16, 1.0, t, now, now,
                              correct_action=c)
                for (s, i, j, t), c in zip(RATINGS, CORRECT, strict=True)
            ],
        )  # fmt: skip
        db.commit()
        people = participants(load_visits(db, made)).set_index("session_id")
    engine.dispose()
    assert people.loc[[ids[1], ids[3]], "accuracy"].tolist() == pytest.approx(
        [ACCURACY[1], ACCURACY[3]]
    )
