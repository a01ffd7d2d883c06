"""A vector task (CartPole-v1, defined in the tests) through `ideeprl batch`: its runs
train the dense network from the task's preset in worker processes, and are stored and
reported like any task's."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, study_id

pytestmark = pytest.mark.slow
CARTPOLE = "tests.tasks.cartpole:cartpole_task"


def test_a_vector_tasks_batch_runs_and_reports(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    batch = [
        "batch", "--study", "cartpole", "--task", CARTPOLE, "--methods", "autonomous",
        "random", "--agents", "2", "--workers", "1", "--report", str(tmp_path / "report"),
        *SCALE,
    ]  # fmt: skip
    code, output = in_process(place, capsys, *batch)
    assert code == 0, output
    engine = place.engine()
    rows = sessions(engine, study_id(engine, "cartpole"))
    assert len(rows) == 4 and all(s.status == "finished" for s in rows), output
    assert {s.spec.preset for s in rows} == {"modern"} and {s.spec.task for s in rows} == {CARTPOLE}
    methods = pd.read_csv(tmp_path / "report" / "r_t_per_method.csv")
    assert methods["method"].tolist() == ["autonomous", "random"]
    assert methods["agents"].tolist() == [2, 2]
