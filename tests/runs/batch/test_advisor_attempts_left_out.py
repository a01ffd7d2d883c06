"""Every advisor a batch trains for the agent method, each attempt whether it passed its
check or not, used or not, is left out of the compared agents: in the database's report
(`ideeprl report`, power, the API) and in the analysis of the study's export."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from sqlalchemy.orm import Session

from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, study_id

REQUIRE = [a for a in SCALE if a not in ("--advisor-check", "record")]
"""The reduced scale with the default rule: no advisor trained at this scale passes."""
BATCH = ["batch", "--study", "pilot", "--methods", "autonomous", "agent", "--agents", "2"]


@pytest.mark.slow
def test_failed_advisor_attempts_are_not_counted_as_autonomous_agents(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from analysis.__main__ import main as analyse
    from study.services.reports import ReportRequest, select_sessions

    code, out = in_process(place, capsys, *BATCH, *REQUIRE, "--advisor-attempts", "2")
    assert code == 2 and "2 trained advisors failed their check" in out, out
    code, preview = in_process(
        place, capsys, *BATCH, *REQUIRE, "--advisor-attempts", "2", "--dry-run"
    )
    assert code == 0 and preview.count("failed its check") == 2, preview  # both attempts'
    assert "2 attempts failed" in preview, preview
    code, out = in_process(place, capsys, *BATCH, *SCALE)  # goes on, the first one advising
    assert code == 0, out

    engine = place.engine()
    every = sessions(engine, study_id(engine, "pilot"))
    advisors = sorted(s.id for s in every if s.seed >= 100_000)
    assert len(advisors) == 2 and all(
        s.label == "baselines advisor" for s in every if s.id in advisors
    )
    agents = {s.id for s in every if s.id not in advisors}
    assert sorted(s.method for s in every if s.id in agents) == ["agent"] * 2 + ["autonomous"] * 2
    note = f"Left out session(s) {', '.join(map(str, advisors))}: advisor(s) trained"

    with Session(engine) as db:  # what the report, power and the API's report compare
        chosen, notes = select_sessions(db, study_id(engine, "pilot"), ReportRequest())
    assert {s.id for s in chosen} == agents, [(s.id, s.method, s.seed) for s in chosen]
    assert any(n.startswith(note) and "2 failed their check" in n for n in notes), notes

    code, out = in_process(
        place, capsys, "report", "--study", "pilot", "--out", str(tmp_path / "r")
    )
    assert code == 0, out
    report = (tmp_path / "r" / "report.md").read_text()
    assert "4 agents in 2 methods" in report and note in report, report[:1500]

    code, out = in_process(
        place, capsys, "export", "--study", "pilot", "--out", str(tmp_path / "x")
    )
    assert code == 0, out
    exported = pd.read_csv(tmp_path / "x" / "sessions.csv")
    assert sorted(exported.loc[exported["advises"], "session_id"]) == advisors
    assert analyse([str(tmp_path / "x"), str(tmp_path / "a")]) == 0
    analysed = (tmp_path / "a" / "report.md").read_text()
    assert "4 agents in 2 methods" in analysed and note in analysed, analysed[:1500]

    # an advisor named as the API names it, session:ID, from the command line too
    named = ["batch", "--study", "again", "--methods", "agent", "--agents", "1", *SCALE]
    code, out = in_process(place, capsys, *named, "--advisor-checkpoint", f"session:{advisors[0]}",
                           "--dry-run")  # fmt: skip
    assert code == 0, out
    code, out = in_process(place, capsys, *named, "--advisor-checkpoint", "session:999999")
    assert code == 2 and "names no session of this installation" in out, out
