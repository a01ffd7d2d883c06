"""A small batch through the local process backend: the sessions it leaves in the database,
and the report written from them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from cli.main import main
from study.db.models import Step
from tests.runs.batch.conftest import BASELINES
from tests.runs.batch.helpers import (
    ADVICE,
    EPISODES,
    SCALE,
    Place,
    in_process,
    is_png,
    read_csv,
    sessions,
    study_id,
    training_totals,
)

pytestmark = pytest.mark.slow


def test_the_advisor_trains_first_and_runs_pair_up_by_seed(place: Place, baselines: str) -> None:
    engine = place.engine()
    rows = sessions(engine, study_id(engine, "baselines"))
    assert [s.status for s in rows] == ["finished"] * 5, [s.status_detail for s in rows]
    (advisor,) = [s for s in rows if s.label == "baselines advisor"]
    assert (advisor.method, advisor.seed) == ("autonomous", 100_000)
    runs = [s for s in rows if s.label == "baselines"]
    seeds = {m: sorted(s.seed for s in runs if s.method == m) for m in ("autonomous", "agent")}
    assert seeds == {"autonomous": [0, 1], "agent": [0, 1]}

    final = Path(advisor.checkpoint_path or "")
    assert final.name == "final.pt" and final.is_file()
    agents = [s for s in runs if s.method == "agent"]
    assert all(Path(s.spec.advisor_checkpoint or "") == final.resolve() for s in agents)
    assert advisor.finished_at is not None
    assert all(s.started_at and s.started_at >= advisor.finished_at for s in agents)

    for s in rows:
        config = s.spec.config
        assert (config.pretraining_steps, config.batch_size, s.spec.motion) == (20, 8, "fast")
        assert s.spec.advice_budget == (ADVICE if s.method == "agent" else 0)
    totals = training_totals(engine, [s.id for s in rows])
    assert {n for n, _ in totals.values()} == {EPISODES} and len(totals) == 5


def test_report_tables_match_the_database(
    place: Place, baselines: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    study = study_id(engine, "baselines")
    out = tmp_path / "report"
    code, printed = in_process(
        place, capsys, "report", "--study", str(study), "--out", str(out), "--note", "pilot run"
    )
    assert code == 0, printed
    assert f"report: {out / 'report.md'}" in printed

    for name in (
        "figure5_reward_per_method.png",
        "figure6_individual_agents.png",
        "figure7_correlation.png",
        "cumulative_reward.png",
        "epsilon.png",
    ):
        assert is_png(out / name), name
    rows = sessions(engine, study)
    advisor = next(s for s in rows if s.label.endswith("advisor"))
    runs = [s for s in rows if s.id != advisor.id]
    expected = training_totals(engine, [s.id for s in runs])

    agents = read_csv(out / "r_t_per_agent.csv")
    assert {int(a["session_id"]): float(a["R_T"]) for a in agents} == pytest.approx(
        {s: total for s, (_, total) in expected.items()}
    )
    method_of = {s.id: s.method for s in runs}
    mean = {
        m: sum(t for s, (_, t) in expected.items() if method_of[s] == m) / 2
        for m in ("autonomous", "agent")
    }
    methods = {r["method"]: r for r in read_csv(out / "r_t_per_method.csv")}
    assert float(methods["autonomous"]["R_T"]) == pytest.approx(mean["autonomous"])
    assert float(methods["agent"]["R_T"]) == pytest.approx(mean["agent"])
    difference = mean["agent"] - mean["autonomous"]
    assert float(methods["agent"]["difference"]) == pytest.approx(difference)
    if mean["autonomous"] > 0:  # a percentage only of a positive reference
        gain = difference / mean["autonomous"] * 100
        assert float(methods["agent"]["improvement_pct"]) == pytest.approx(gain)
    else:
        assert methods["agent"]["improvement_pct"] == ""
    tests = {(t["method_a"], t["method_b"], t["sample"]) for t in read_csv(out / "t_tests.csv")}
    assert tests == {
        ("agent", "autonomous", "episode_means"),
        ("agent", "autonomous", "agent_totals"),
    }
    report = (out / "report.md").read_text()
    assert f"Left out session(s) {advisor.id}" in report and "- pilot run" in report
    assert "![Figure 5" in report and "figure7_correlation.png" in report

    # each advised session's advice, counted as its advisor steps in the database did
    quality = {int(r["session_id"]): r for r in read_csv(out / "advice_quality.csv")}
    assert set(quality) == {s.id for s in runs if s.method == "agent"}
    with Session(engine) as db:
        for session_id, row in quality.items():
            advised = db.scalars(
                select(Step.outcome).where(
                    Step.session_id == session_id, Step.action_source == "advisor"
                )
            ).all()
            assert int(row["advice"]) == len(advised) == ADVICE
            assert int(row["placed"]) == advised.count("placed")
    assert "## Advice quality" in report


def test_report_json_is_the_apis_description_of_it(
    place: Place, baselines: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--json`: stdout is the report's description alone (files, R_T per method, notes)."""
    engine = place.engine()
    study = study_id(engine, "baselines")
    out = tmp_path / "scripted"
    capsys.readouterr()
    args = ["report", "--study", "baselines", "--out", str(out), "--json"]
    assert main([*args, *place.flags]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["folder"] == str(out.resolve()) and printed["study_id"] == study
    assert {f["name"] for f in printed["files"]} == {p.name for p in out.glob("*.*")}
    methods = {r["method"]: float(r["R_T"]) for r in read_csv(out / "r_t_per_method.csv")}
    assert {m["method"]: m["R_T"] for m in printed["methods"]} == pytest.approx(methods)
    assert printed["baseline"] == "autonomous" and printed["warnings"] == []
    advisor = next(s.id for s in sessions(engine, study) if s.label.endswith("advisor"))
    assert any(f"Left out session(s) {advisor}" in note for note in printed["notes"])


def test_the_same_command_again_runs_nothing(
    place: Place, baselines: str, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    study = study_id(engine, "baselines")
    before = [(s.id, s.finished_at, s.checkpoint_path) for s in sessions(engine, study)]
    code, out = in_process(place, capsys, *BASELINES, *SCALE)
    assert code == 0, out
    assert "5 runs (2 autonomous, 2 agent and the advisor): 5 finished already" in out
    assert [(s.id, s.finished_at, s.checkpoint_path) for s in sessions(engine, study)] == before


def test_the_report_command_names_the_runs_it_took_over(
    place: Place, baselines: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A batch under a new label takes over the finished runs of the same description, which
    keep their label: the report command it prints names them by session, not by label."""
    engine = place.engine()
    study = study_id(engine, "baselines")
    compared = [s.id for s in sessions(engine, study) if not s.label.endswith("advisor")]
    code, out = in_process(place, capsys, *BASELINES, *SCALE, "--label", "renamed")
    assert code == 0, out
    hint = out.split("report: ", 1)[1].splitlines()[0]
    assert " --label " not in hint
    assert f" --sessions {' '.join(map(str, sorted(compared)))} --out DIR " in hint
    assert f"--data-dir {place.data_dir}" in hint
    code, out = in_process(place, capsys, *BASELINES, *SCALE)
    assert "--label baselines --out DIR" in out.split("report: ", 1)[1].splitlines()[0]


def test_runs_are_identified_by_their_configuration(
    place: Place, baselines: str, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    ids = [s.id for s in sessions(engine, study_id(engine, "baselines"))]
    code, same = in_process(place, capsys, *BASELINES, *SCALE, "--label", "renamed", "--dry-run")
    assert code == 0, same
    assert same.count(": finished") == 5 and all(f"session {i}:" in same for i in ids)

    assert SCALE[:2] == ["--episodes", "2"]
    longer = ["--episodes", "3", *SCALE[2:]]
    code, changed = in_process(place, capsys, *BASELINES, *longer, "--dry-run")
    assert code == 0, changed
    assert "finished" not in changed.split("database", 1)[1]
    assert changed.count(" new") == 3 and changed.count("waits for the advisor") == 2
    assert [s.id for s in sessions(engine, study_id(engine, "baselines"))] == ids
