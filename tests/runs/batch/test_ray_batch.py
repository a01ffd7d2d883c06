"""The same batch on Ray: a local Ray instance (two CPUs) started by the command."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.runs.batch.helpers import (
    EPISODES,
    SCALE,
    Place,
    ideeprl,
    read_csv,
    sessions,
    study_id,
    training_totals,
)

pytestmark = pytest.mark.slow


def test_a_batch_on_a_local_ray_instance(place: Place, tmp_path: Path) -> None:
    pytest.importorskip("ray")
    out = tmp_path / "report"
    done = ideeprl(
        place,
        "batch", "--study", "on ray", "--methods", "autonomous", "oracle", "--agents", "2",
        *SCALE, "--backend", "ray", "--workers", "2", "--population", "2",
        "--report", str(out),
        timeout=400,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    engine = place.engine()
    rows = sessions(engine, study_id(engine, "on ray"))
    assert [(s.method, s.seed, s.status) for s in rows] == [
        ("autonomous", 0, "finished"),
        ("oracle", 0, "finished"),
        ("autonomous", 1, "finished"),
        ("oracle", 1, "finished"),
    ]
    # Two Ray tasks side by side, each a population of two (agent by agent, as planned).
    pids = [s.provenance[-1]["pid"] for s in rows]
    assert len(set(pids)) == 2 and pids[0] == pids[1] and pids[2] == pids[3], pids
    assert {s.worker_pid for s in rows} == {None}, "no process runs them now"
    assert {s.provenance[-1]["population"]["population_size"] for s in rows} == {2}
    totals = training_totals(engine, [s.id for s in rows])
    assert {n for n, _ in totals.values()} == {EPISODES}
    agents = {int(a["session_id"]): float(a["R_T"]) for a in read_csv(out / "r_t_per_agent.csv")}
    assert agents == pytest.approx({s: total for s, (_, total) in totals.items()})
    report = (out / "report.md").read_text()
    assert "Command: `ideeprl batch --study 'on ray'" in report and "--backend ray" in report
    assert "torch" in report and "pybullet" in report
