"""Pre-registration: a design's primary measure and test, checked when the design is given
(a 422 for values that do not fit), leading the report with the power the study had for
its observed spread, every other test marked exploratory."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError
from scipy import stats

from analysis.preregistration import Preregistered, preregistered
from analysis.primary import detectable, primary_lines
from analysis.report import write_human_report
from server.main import create_app
from study.schemas.design import StudyDesign
from study.settings import Settings
from tests.analysis.visits import hand_visits
from tests.server.live import API_KEY

RUN = {"method": "human"}


def _design(primary: dict[str, Any], conditions: tuple[str, ...] = ("early", "late")) -> Any:
    return {"conditions": {c: {"run": RUN} for c in conditions}, "primary": primary}


@pytest.mark.parametrize(
    ("primary", "conditions", "says"),
    [
        ({"measure": "trust", "test": "fisher"}, ("early", "late"), "must be welch or"),
        ({"measure": "completed", "test": "welch"}, ("early", "late"), "must be fisher"),
        ({"measure": "speed", "test": "welch"}, ("early", "late"), "Input should be"),
        ({"measure": "trust", "test": "welch"}, ("a", "b", "c"), "name the two conditions"),
        ({"measure": "trust", "test": "welch", "conditions": ["early", "x"]}, ("early", "late"),
         "'x' is not one of"),
        ({"measure": "trust", "test": "welch", "effect": -1}, ("early", "late"), "greater than"),
    ],
)  # fmt: skip
def test_a_primary_that_does_not_fit_is_refused(
    primary: dict[str, Any], conditions: tuple[str, ...], says: str
) -> None:
    with pytest.raises(ValidationError, match=says):
        StudyDesign.model_validate(_design(primary, conditions))


def test_the_api_refuses_a_bad_primary_with_a_422_and_keeps_a_good_one(tmp_path: Path) -> None:
    settings = Settings(
        data_dir=tmp_path / "data", database_url=f"sqlite:///{tmp_path / 'db'}", api_key=API_KEY
    )
    with TestClient(create_app(settings)) as client:
        headers = {"X-API-Key": API_KEY}
        bad = _design({"measure": "check_passed", "test": "mann_whitney"})
        refused = client.post("/api/studies", json={"name": "r", "design": bad}, headers=headers)
        assert refused.status_code == 422 and "must be fisher" in refused.text
        good = _design({"measure": "trust", "test": "welch", "effect": 2})
        taken = client.post("/api/studies", json={"name": "g", "design": good}, headers=headers)
        assert taken.status_code == 201, taken.text
        stored = client.get(f"/api/studies/{taken.json()['id']}", headers=headers).json()
    plan = preregistered(stored["design"])
    assert plan == Preregistered("trust", "welch", ("early", "late"), 2.0)


def test_the_report_leads_with_the_primary_test_and_its_power(tmp_path: Path) -> None:
    plan = Preregistered("trust", "welch", ("early", "late"), effect=2.0)
    result = write_human_report(
        hand_visits(), tmp_path, title="t", notes=["a note"], preregistered=plan
    )
    text = result.report.read_text()
    sections = [line for line in text.splitlines() if line.startswith("## ")]
    assert sections[0] == "## Primary test (pre-registered)"
    # trust: early 5, 6, 4 (sd 1), late 3, 2 (sd sqrt(0.5)); the smaller group has 2
    t = 2.5 / math.sqrt(1 / 3 + 0.5 / 2)
    assert f"statistic {t:.3g}" in text
    smallest = (stats.norm.ppf(0.975) + stats.norm.ppf(0.8)) * math.sqrt((1 + 0.5) / 2)
    assert detectable(1.0, math.sqrt(0.5), 2, 0.05) == pytest.approx(smallest)
    assert f"a difference of {smallest:.3g} was detectable with 80% power" in text
    se = math.sqrt(1.5 / 2)
    had = stats.norm.cdf(2 / se - stats.norm.ppf(0.975)) + stats.norm.cdf(
        -2 / se - stats.norm.ppf(0.975)
    )
    assert f"worth detecting, 2, with {had:.0%}" in text
    assert "Every other test in this report is exploratory" in text
    tests = pd.read_csv(tmp_path / "participants_tests.csv")
    assert set(tests["role"]) == {"exploratory"}


def test_a_primary_with_one_participant_says_no_test_yet() -> None:
    visits = hand_visits()
    late_one = visits.sessions[visits.sessions["session_id"] != 7]
    visits = type(visits)(
        late_one, visits.advice, visits.check, visits.questionnaire, visits.scales
    )
    lines = primary_lines(Preregistered("trust", "welch", ("early", "late")), visits, None, 0.05)
    assert any(line.startswith("No test yet") for line in lines)
    assert any(line.startswith("No power can be stated yet") for line in lines)


def test_a_rate_is_tested_with_fishers_exact_test() -> None:
    plan = Preregistered("completed", "fisher", ("early", "late"))
    text = "\n".join(primary_lines(plan, hand_visits(), None, 0.05))
    # completed of consented: early 3 of 4, late 2 of 4
    p = stats.fisher_exact([[3, 1], [2, 2]]).pvalue
    assert f"p = {p:.3g}" in text and "early: 4, late: 4" in text
