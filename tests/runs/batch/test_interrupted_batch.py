"""Kill a batch's runner in the middle; the same command again finishes only what is
missing, resuming the interrupted run from its checkpoint. Then report on a study that has
no autonomous baseline."""

from __future__ import annotations

import shlex
import time
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from study.db.models import Episode
from tests.runs.batch.helpers import (
    SCALE,
    Place,
    in_process,
    read_csv,
    sessions,
    start_ideeprl,
    study_id,
    training_totals,
)

pytestmark = pytest.mark.slow
EPISODES = 10
ADVISED = ["batch", "--study", "advised only", "--methods", "oracle,random", "--agents", "1"]
ADVISED += ["--workers", "1", "--error-rate", "0.2", "--episodes", str(EPISODES)]
ADVISED += ["--population", "1"]  # one run after the other (a killed population: its own test)
ADVISED += SCALE[2:]  # the reduced scale, with more episodes: time to interrupt the second run
assert SCALE[0] == "--episodes"


def episode_ids(place: Place, session_id: int) -> list[tuple[int, int]]:
    with Session(place.engine()) as db:
        query = select(Episode.id, Episode.episode).where(
            Episode.session_id == session_id, Episode.stage == "train"
        )
        return [(int(i), int(e)) for i, e in db.execute(query.order_by(Episode.episode))]


def wait_for(what: str, condition: object, log: Path, timeout: float = 150) -> None:
    deadline = time.monotonic() + timeout
    while not condition():  # type: ignore[operator]
        assert time.monotonic() < deadline, f"timed out waiting for {what}:\n{log.read_text()}"
        time.sleep(0.1)


def test_a_killed_batch_resumes_with_the_missing_runs_only(
    place: Place, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    log = tmp_path / "runner.log"
    runner = start_ideeprl(place, *ADVISED, log=log)

    def first_done_second_checkpointed() -> bool:
        assert runner.poll() is None, log.read_text()
        try:
            rows = sessions(engine, study_id(engine, "advised only"))
        except (AssertionError, OperationalError):
            return False  # the study (or, while the runner migrates, its table) is not there yet
        return (
            len(rows) == 2
            and rows[0].status == "finished"
            and rows[1].status == "running"
            and rows[1].checkpoint_episodes >= 1
        )

    wait_for("one run finished, one checkpointed", first_done_second_checkpointed, log)
    runner.kill()
    runner.wait()
    study = study_id(engine, "advised only")
    # Its worker notices the runner is gone, checkpoints and lets the session go.
    wait_for(
        "the orphaned worker to interrupt its session",
        lambda: sessions(engine, study)[1].status == "interrupted",
        log,
        timeout=60,
    )
    finished, interrupted = sessions(engine, study)
    assert interrupted.checkpoint_episodes < EPISODES
    finished_rows = episode_ids(place, finished.id)

    code, again = in_process(place, capsys, *ADVISED)
    assert code == 0, again
    assert "2 runs (1 oracle, 1 random): 1 finished already, 1 to resume" in again
    after = sessions(engine, study)
    assert [s.id for s in after] == [finished.id, interrupted.id]  # no run created twice
    assert after[0].finished_at == finished.finished_at
    assert episode_ids(place, finished.id) == finished_rows  # untouched, row for row
    assert after[1].status == "finished" and after[1].started_at == interrupted.started_at
    assert [e for _, e in episode_ids(place, interrupted.id)] == list(range(1, EPISODES + 1))

    # No autonomous baseline in this study: the report compares the two methods as they are.
    out = tmp_path / "report"
    code, printed = in_process(place, capsys, "report", "--study", str(study), "--out", str(out))
    assert code == 0, printed
    assert "No autonomous DeepRL sessions in this report" in printed
    methods = {r["method"]: r for r in read_csv(out / "r_t_per_method.csv")}
    assert set(methods) == {"oracle", "random"}
    assert all(r["improvement_pct"] == "" for r in methods.values())
    totals = training_totals(engine, [s.id for s in after])
    for s in after:
        assert float(methods[s.method]["R_T"]) == pytest.approx(totals[s.id][1])
    assert "Baseline: none" in (out / "report.md").read_text()

    # The report says how to add the baseline; its command, run as given, makes one that the
    # next report compares against, under the same settings (no warning that they differ).
    suggested = printed.split("with the same settings", 1)[1].split("`")[1]
    assert suggested.startswith(f"ideeprl batch --study {study} --methods autonomous")
    code, ran = in_process(place, capsys, *shlex.split(suggested)[1:])
    assert code == 0, ran
    code, printed = in_process(place, capsys, "report", "--study", str(study), "--out", str(out))
    assert code == 0, printed
    assert "No autonomous DeepRL sessions" not in printed and "not comparable" not in printed
    methods = {r["method"]: r for r in read_csv(out / "r_t_per_method.csv")}
    assert set(methods) == {"autonomous", "oracle", "random"}
    assert all(methods[m]["difference"] != "" for m in ("oracle", "random"))
