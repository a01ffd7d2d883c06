"""A report of a task other than the sorting robot speaks of that task's own measures: its
per-method table and advice quality have no placements (all 0 there, and meaningless) but
each method's and each advised agent's success rate; a study that ran the sorting robot
keeps its placements."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import write_report
from tests.analysis.test_audit import settings_for
from tests.analysis.test_report import study_episodes

ROBOT_WORDS = ("placed", "misplaced", "lost", "placement")


def _episodes() -> pd.DataFrame:
    """The report tests' study, with the counts an export gives every task: the robot's
    placements (0 in the grid world), steps and success."""
    episodes = study_episodes()
    rng = np.random.default_rng(5)
    return episodes.assign(
        steps=20, placed_correct=0, misplaced=0, lost=0,
        success=rng.random(len(episodes)) < np.where(episodes["method"] == "autonomous", 0.5, 0.9),
    )  # fmt: skip


def _advice(episodes: pd.DataFrame) -> pd.DataFrame:
    """Eight advised steps of each advised session, moves 0 to 3 in turn."""
    advised = episodes.loc[episodes["method"] != "autonomous", "session_id"].unique()
    rows = [(s, step, step % 4, None) for s in advised for step in range(1, 9)]
    return pd.DataFrame(rows, columns=["session_id", "global_step", "action", "outcome"])


def _section(text: str, heading: str) -> str:
    return text.split(heading, 1)[1].split("\n## ", 1)[0]


@pytest.mark.slow
def test_a_grid_world_report_shows_success_rates_and_no_placements(tmp_path: Path) -> None:
    episodes = _episodes()
    settings = settings_for(episodes).assign(task="gridworld")
    result = write_report(
        episodes, tmp_path / "grid", settings=settings, advice=_advice(episodes), power_draws=50
    )
    text = result.report.read_text()
    methods = pd.read_csv(result.tables["methods"])
    assert not any(c.startswith(("placed", "misplaced", "lost")) for c in methods.columns)
    rates = episodes.groupby("method")["success"].mean()
    assert dict(zip(methods["method"], methods["success_rate"], strict=True)) == pytest.approx(
        rates.to_dict()
    )
    assert "success rate (of its episodes)" in text and "steps / episode" in text
    quality = _section(text, "## Advice quality")
    assert "| agent | method | advice | longest repeat | success rate | R_T |" in quality
    for word in ROBOT_WORDS:
        assert word not in quality and f"{word} / episode" not in text, word
    table = pd.read_csv(result.tables["advice_quality"])
    assert "placed" not in table and len(table) == 9
    by_session = episodes.groupby("session_id")["success"].mean()
    assert table["success_rate"].tolist() == pytest.approx(by_session[table["session_id"]].tolist())
    assert "advice_correlations" not in result.tables
    linked = re.findall(r"- \[([^\]]+)\]\(", _section(text, "## Files"))
    assert "advice_quality.csv" in linked, "every file the report names is there"
    assert all((tmp_path / "grid" / name).exists() for name in linked), linked

    robot = write_report(
        episodes, tmp_path / "robot", settings=settings.assign(task="sorting"),
        advice=_advice(episodes), power_draws=50,
    )  # fmt: skip
    text = robot.report.read_text()
    assert "placed correct / episode" in text
    assert "| agent | method | advice | placed | misplaced | lost |" in text
