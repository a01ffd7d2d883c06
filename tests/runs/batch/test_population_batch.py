"""Populations through the real command line (`ideeprl batch --population N`): an agent's
records in a population are its records alone, whatever its population mates' methods and
reward schemes, and a population whose worker is killed resumes to the same records."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import func, select
from sqlalchemy.engine import Engine
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from study.db.migrate import upgrade
from study.db.models import Advice, Step, StudySession
from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, start_ideeprl, study_id

pytestmark = pytest.mark.slow
MIXED = ["--methods", "autonomous,agent,procedure", "--agents", "2", "--workers", "1"]
MIXED += ["--per-method", "agent:reward_scheme=authors-interactive", *SCALE]
"""Three methods, the agent runs (and their procedure controls) on another reward scheme:
with one worker and populations of up to 3, the batch trains [autonomous 1, agent 1,
autonomous 2] (two methods, two schemes), then [procedure 1, agent 2] (the control beside
an advised run), then procedure 2 alone."""
DECISIVE = (
    Step.global_step, Step.stage, Step.episode, Step.action, Step.action_source,
    Step.greedy_action, Step.advised_action, Step.reward, Step.terminated, Step.truncated,
    Step.observation_hash,
)  # fmt: skip
"""The columns that decide an agent's course: equal to the bit alone and in a population."""
Q_VALUES = (Step.q_grab, Step.q_move_right, Step.q_move_left, Step.q_drop, Step.loss)
Q_TOLERANCE = 1e-5
"""Relative: with one torch thread and the per-agent convolutions they are equal to the bit
too (tests/learner/test_population.py); the batch test allows float noise in the stored
REAL column."""


def steps(engine: Engine, session_id: int) -> tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]:
    """The session's step records: the decisive columns, and the Q-values and losses."""
    with Session(engine) as db:
        query = select(*DECISIVE, *Q_VALUES).where(Step.session_id == session_id)
        rows = [tuple(r) for r in db.execute(query.order_by(Step.global_step))]
    return [r[: len(DECISIVE)] for r in rows], [r[len(DECISIVE) :] for r in rows]


def advice(engine: Engine, session_id: int) -> list[tuple[Any, ...]]:
    with Session(engine) as db:
        query = select(Advice.global_step, Advice.action).where(Advice.session_id == session_id)
        return [tuple(r) for r in db.execute(query.order_by(Advice.advice_index))]


def by_run(engine: Engine, name: str) -> dict[tuple[str, int], StudySession]:
    return {(s.method, s.seed): s for s in sessions(engine, study_id(engine, name))}


def population_of(session: StudySession) -> dict[str, Any] | None:
    return session.provenance[-1].get("population") if session.provenance else None


def assert_same_records(engine: Engine, alone: StudySession, together: StudySession) -> None:
    what = f"{together.method} seed {together.seed}"
    decisive, q = steps(engine, together.id)
    decisive_alone, q_alone = steps(engine, alone.id)
    assert decisive and decisive == decisive_alone, what
    nan = float("nan")
    for row, row_alone in zip(q, q_alone, strict=True):
        values, expected = ([nan if v is None else v for v in r] for r in (row, row_alone))
        assert values == pytest.approx(expected, rel=Q_TOLERANCE, nan_ok=True), what
    assert advice(engine, together.id) == advice(engine, alone.id), what


@pytest.fixture(scope="module")
def alone(place: Place) -> dict[tuple[str, int], StudySession]:
    """The mixed batch with every run alone (the reference)."""
    code, out = in_process_plain(place, "batch", "--study", "alone", *MIXED, "--population", "1")
    assert code == 0, out
    assert "populations:" not in out
    return by_run(place.engine(), "alone")


def in_process_plain(place: Place, *args: str) -> tuple[int, str]:
    """`in_process` for a fixture (no capsys): exit code and output."""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from cli.main import main

    output = io.StringIO()
    with redirect_stdout(output), redirect_stderr(output):
        code = main([*args, *place.flags])
    return code, output.getvalue()


def test_agents_in_populations_keep_their_own_records_methods_and_schemes(
    place: Place, alone: dict[tuple[str, int], StudySession], capsys: pytest.CaptureFixture[str]
) -> None:
    advisor = alone[("autonomous", 100_000)]
    code, out = in_process(
        place, capsys, "batch", "--study", "together", *MIXED, "--population", "3",
        "--advisor-checkpoint", str(advisor.checkpoint_path),
    )  # fmt: skip
    assert code == 0, out
    assert "populations: up to 3 runs of one learner configuration" in out
    engine = place.engine()
    together = by_run(engine, "together")
    assert len(together) == 6 and all(s.status == "finished" for s in together.values())
    sizes: dict[int, list[StudySession]] = {}
    for run, session in together.items():
        numerics = population_of(session) or {"population_size": 1}  # alone: a plain run
        assert numerics.get("seed", session.seed) == session.seed
        sizes.setdefault(numerics["population_size"], []).append(session)
        assert_same_records(engine, alone[run], session)
        assert (
            session.run["scenario"]["reward_scheme"] == alone[run].run["scenario"]["reward_scheme"]
        )
    # Mixed populations: methods and reward schemes side by side, each agent its own.
    mixed = {(s.method, s.run["scenario"]["reward_scheme"]) for s in sizes[3]}
    assert mixed == {("autonomous", "paper"), ("agent", "authors-interactive")}
    assert {s.method for s in sizes[2]} == {"procedure", "agent"}
    assert [(s.method, s.seed) for s in sizes[1]] == [("procedure", 1)]
    assert {population_of(s)["layout"] for s in sizes[3] + sizes[2]} == {"stacked-actions"}  # type: ignore[index]
    # Advice reached the advised agents in populations, and not the others.
    assert all(advice(engine, s.id) for s in together.values() if s.method != "autonomous")
    assert not any(advice(engine, s.id) for s in together.values() if s.method == "autonomous")


KILLED = ["--methods", "autonomous", "--agents", "3", "--workers", "1", *SCALE]
KILLED += ["--episodes", "12"]


def test_a_population_whose_worker_is_killed_resumes_to_the_same_records(
    place: Place, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = place.engine()
    code, out = in_process(
        place, capsys, "batch", "--study", "kill ref", *KILLED, "--population", "1"
    )
    assert code == 0, out
    log = tmp_path / "runner.log"
    killed = [*KILLED, "--population", "3"]
    runner = start_ideeprl(place, "batch", "--study", "killed", *killed, log=log)

    def mid_run() -> list[StudySession] | None:
        assert runner.poll() is None, log.read_text()
        try:
            rows = sessions(engine, study_id(engine, "killed"))
        except (AssertionError, OperationalError):
            return None  # not created yet
        running = [s for s in rows if s.status == "running" and s.worker_pid]
        if len(running) == 3 and min(s.checkpoint_episodes for s in running) >= 2:
            return running
        return None

    deadline = time.monotonic() + 150
    while (running := mid_run()) is None:
        assert time.monotonic() < deadline, log.read_text()
        time.sleep(0.05)
    assert len({s.worker_pid for s in running}) == 1  # one process trains all three
    os.kill(running[0].worker_pid, signal.SIGKILL)  # type: ignore[arg-type]
    assert runner.wait(timeout=120) == 1, log.read_text()  # incomplete: run it again
    interrupted = sessions(engine, study_id(engine, "killed"))
    assert all(s.status == "interrupted" for s in interrupted), log.read_text()
    assert all(s.checkpoint_episodes < 12 for s in interrupted)

    code, again = in_process(place, capsys, "batch", "--study", "killed", *killed)
    assert code == 0, again
    assert "3 to resume" in again
    reference = by_run(engine, "kill ref")
    for run, session in by_run(engine, "killed").items():
        assert session.status == "finished"
        assert population_of(session)["population_size"] == 3  # type: ignore[index]
        assert_same_records(engine, reference[run], session)


def test_an_error_in_a_population_fails_its_agents_and_each_resumes(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    """A real fault: the second agent's checkpoint folder is a file, so its first checkpoint
    raises; every agent still training fails with the traceback, and the same command, once
    the fault is gone, resumes both from their last checkpoints to the end."""
    engine = place.engine()
    upgrade(engine)  # the tables, when this test runs first
    with Session(engine) as db:  # the batch creates the next two sessions, in plan order
        last = db.scalar(select(func.max(StudySession.id))) or 0
    blocker = place.data_dir / "checkpoints" / f"session-{last + 2}"
    blocker.parent.mkdir(parents=True, exist_ok=True)
    blocker.write_text("not a folder")
    failing = ["batch", "--study", "failing", "--methods", "autonomous", "--agents", "2"]
    failing += ["--workers", "1", "--population", "2", *SCALE]
    code, out = in_process(place, capsys, *failing)
    assert code == 1, out
    rows = sessions(engine, study_id(engine, "failing"))
    assert [s.id for s in rows] == [last + 1, last + 2]
    assert [s.status for s in rows] == ["failed", "failed"], out
    assert all("FileExistsError" in (s.status_detail or "") for s in rows)
    blocker.unlink()
    code, again = in_process(place, capsys, *failing)
    assert code == 0, again
    assert "failed before; it resumes from its last checkpoint" in again
    assert [s.status for s in sessions(engine, study_id(engine, "failing"))] == ["finished"] * 2
