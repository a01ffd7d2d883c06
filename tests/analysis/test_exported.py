"""A study's export reads back for the analysis: an export written by the version before
the run was one document (API 1.x, committed under tests/fixtures/) gives each session's
run from its columns, the episode table and the steps, and the report with its audit."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from analysis import write_report
from analysis.__main__ import main
from analysis.exported import ExportError, read_export

OLD_EXPORT = Path(__file__).parents[1] / "fixtures" / "export-1.x"
"""`ideeprl export` of a tiny batch (2 autonomous, 2 oracle agents; oracle 10 % wrong under
authors-interactive, knock-offs 0.1 for all), written by commit dc7b896."""


def _rows(name: str) -> list[dict[str, str]]:
    with (OLD_EXPORT / name).open() as f:
        return list(csv.DictReader(f))


def test_an_export_of_the_previous_version_reads_back_as_runs() -> None:
    export = read_export(OLD_EXPORT)
    sessions = {int(r["session_id"]): r for r in _rows("sessions.csv")}
    assert set(export.runs) == set(sessions)
    for session_id, run in export.runs.items():
        row = sessions[session_id]
        assert (run.method, run.seed) == (row["method"], int(row["seed"]))
        assert run.config.batch_size == int(row["config_batch_size"]) == 8
        assert run.config.episodes == int(row["episodes"])
        assert run.scenario.knock_off_rate == float(row["knock_off_rate"]) == 0.1
        assert run.validate() == run.normalized()
    oracle = [r for r in export.runs.values() if r.method == "oracle"]
    assert {r.error_rate for r in oracle} == {0.1} and len(oracle) == 2
    assert {r.scenario.reward_scheme for r in oracle} == {"authors-interactive"}
    assert {r.strategy for r in oracle} == {"early"} and {r.advice_budget for r in oracle} == {8}
    totals = export.episodes.groupby("session_id")["collected_reward"].sum()
    for session_id in export.runs:
        logged = [r for r in _rows("episodes.csv") if int(r["session_id"]) == session_id]
        train = [float(r["collected_reward"]) for r in logged if r["phase"] == "train"]
        assert totals[session_id] == pytest.approx(sum(train))
    assert set(export.steps["session_id"]) == set(export.runs)


@pytest.mark.slow
def test_the_report_of_an_old_export_audits_what_it_compares(tmp_path: Path) -> None:
    export = read_export(OLD_EXPORT)
    result = write_report(export.episodes, tmp_path, settings=export.settings, steps=export.steps)
    assert result.audit is not None and not result.audit.comparable
    assert "reward scheme" in result.audit.differ("autonomous", "oracle")
    assert main([str(OLD_EXPORT), str(tmp_path / "cli")]) == 0
    text = (tmp_path / "cli" / "report.md").read_text()
    assert "Comparability warning" in text and "rescored" in text.lower()


def test_a_folder_that_is_no_export_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="not a study export"):
        read_export(tmp_path)
    assert main([str(tmp_path), str(tmp_path / "out")]) == 2


def _as_online_study(folder: Path, alpha: float) -> dict[int, str]:
    """The fixture's export rewritten as an online study's: its `study.json` with a design
    (α, two conditions) and a condition per session, as today's export writes them."""
    shutil.copytree(OLD_EXPORT, folder)
    with (folder / "sessions.csv").open() as f:
        rows = list(csv.DictReader(f))
    names = {"autonomous": "no-advice", "oracle": "advised"}
    for row in rows:
        row["condition"] = names[row["method"]]
    with (folder / "sessions.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    study = json.loads((folder / "study.json").read_text())
    conditions = {name: {"run": {"method": method}} for method, name in names.items()}
    study["design"] = {"alpha": alpha, "conditions": conditions}
    (folder / "study.json").write_text(json.dumps(study))
    return {int(row["session_id"]): row["condition"] for row in rows}


@pytest.mark.slow
def test_an_online_studys_export_compares_its_conditions_at_its_alpha(tmp_path: Path) -> None:
    folder = tmp_path / "online"
    conditions = _as_online_study(folder, alpha=0.01)
    export = read_export(folder)
    assert export.conditions == conditions and export.alpha == 0.01
    assert main([str(folder), str(tmp_path / "auto")]) == 0
    text = (tmp_path / "auto" / "report.md").read_text()
    assert "conditions are compared, at α = 0.01" in text
    assert "No autonomous DeepRL sessions" in text, "no method is named 'autonomous' now"
    assert "advised" in text and "no-advice" in text
    assert main([str(folder), str(tmp_path / "vs"), "--baseline", "no-advice"]) == 0
    assert main([str(folder), str(tmp_path / "none"), "--baseline", "none"]) == 0
    assert main([str(folder), str(tmp_path / "bad"), "--baseline", "autonomous"]) == 2
    assert not (tmp_path / "bad").exists()
