"""A population's worker: sessions whose runs share one learner configuration, trained
together in one process (`learner.population.Population`), each writing its own records
exactly as it would alone.

Each agent is its session's run as `runs.worker.worker` builds it (its recorder and
progress reporter as the trainer's callbacks, its machine advice recorded, its checkpoint
resumed), built without a channel; the population steps their trainers together, and
between two steps every run does what it does alone (heartbeat, flush, a checkpoint every
few episodes). An agent that finishes writes its final checkpoint and leaves; the others
go on. Its checkpoints are `Trainer` checkpoints (`Population.save_checkpoint`): a session
resumes alone or in another population, of any size.

The population's size and layout are recorded with each agent: in the session's
provenance entry for this start (`population`) and in its checkpoints' metadata.

The channel to the runner is one `WorkerLink` for the whole population: a shutdown (or a
runner that died) checkpoints every agent at the step boundary and leaves each session
`interrupted`. An error in a step fails every agent still training (each resumes from its
last checkpoint when the batch runs again): the agents' steps are interleaved, so no agent
can be told apart as the one at fault.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import update

from learner.config import DQNConfig, shared_config
from learner.run import RunSpec
from runs.worker.link import WorkerExit, WorkerLink
from runs.worker.recorder import LeaseLost
from runs.worker.worker import WorkerOptions, _Run, claim_session, fail_session
from study.db.engine import make_engine, make_session_factory
from study.db.models import Status, StudySession

if TYPE_CHECKING:
    from learner.population import Population

log = logging.getLogger(__name__)
NOT_RUN = "not run: "
"""How a worker reports a session it could not claim (another runner has it)."""


@dataclass(frozen=True)
class AgentSaver:
    """Agent `index`'s checkpoints, with the population's numerics in their metadata
    (`runs.worker.recorder.Checkpointable`)."""

    population: Population
    index: int

    def save_checkpoint(self, path: str | os.PathLike[str], *, memory: bool = True) -> None:
        self.population.save_checkpoint(self.index, Path(path), memory=memory)


def run_population(
    session_ids: Sequence[int],
    database_url: str,
    options: WorkerOptions,
    conn: Connection | None = None,
    ended: Callable[[int, str], None] = lambda session_id, status: None,
) -> dict[int, str]:
    """Run the sessions to their end together in this process; returns each one's final
    status (as `run_session` gives it, `NOT_RUN` and why for one it could not claim), and
    calls `ended(session_id, status)` as each ends (an agent that finishes early is
    reported at once)."""
    if options.nice:
        os.nice(options.nice)
    factory = make_session_factory(make_engine(database_url))
    statuses: dict[int, str] = {}

    def end(session_id: int, status: str) -> None:
        statuses[session_id] = status
        ended(session_id, status)

    runs: list[_Run] = []
    for session_id in session_ids:
        try:
            token = claim_session(factory, session_id, options)
        except Exception as error:  # someone else runs it, or it is gone
            end(session_id, f"{NOT_RUN}{error}")
            continue
        try:
            from learner.trainer import Trainer  # torch: loaded in the worker, not the runner

            run = _Run(session_id, database_url, options, token, None)
            if not isinstance(run.trainer, Trainer):
                raise ValueError(f"session {session_id}'s learner cannot join a population")
            runs.append(run)
        except LeaseLost as error:
            log.warning("%s", error)
            end(session_id, "lost")
        except Exception as error:
            fail_session(factory, session_id, token, error)
            end(session_id, Status.failed.value)
    if runs:
        _train(runs, conn, end, statuses)
    return statuses


def _train(
    runs: list[_Run],
    conn: Connection | None,
    end: Callable[[int, str], None],
    ended: dict[int, str],
) -> None:
    """Step the runs together until each has ended; `ended` holds those that have."""
    from learner.population import Population

    try:
        population = Population.of([run.trainer for run in runs])  # type: ignore[misc]
    except ValueError as error:  # their numerics were settled apart when claimed
        for run in runs:
            fail_session(run.factory, run.session_id, run.token, error)
            end(run.session_id, Status.failed.value)
        return
    try:
        for index, run in enumerate(runs):
            run.saver = AgentSaver(population, index)
            _record_numerics(run, population.numerics(index))
        _step_until_done(population, runs, conn, end)
    except Exception as error:  # every run not ended yet fails (a finish that failed too)
        for run in runs:
            if run.session_id not in ended:
                fail_session(run.factory, run.session_id, run.token, error)
                end(run.session_id, Status.failed.value)
    finally:
        population.close()


def _step_until_done(
    population: Population,
    runs: list[_Run],
    conn: Connection | None,
    end: Callable[[int, str], None],
) -> None:
    link = WorkerLink(conn, _no_pause, _nothing, _ticker(runs, population)) if conn else None
    lost: set[int] = set()
    for index in [i for i in range(population.size) if runs[i].trainer.done]:
        end(runs[index].session_id, runs[index].finish().value)  # resumed at its end
    while not population.done:
        active = population.active
        try:
            if link is not None:
                link.poll()
            for index in active:
                if not _between_steps(runs[index]):
                    lost.add(index)
                    end(runs[index].session_id, "lost")
        except WorkerExit as exit_:
            for index in population.active:
                end(runs[index].session_id, runs[index].exit(exit_, True).value)
            return
        if population.done:
            return
        population.step()
        for index in active:
            if runs[index].trainer.done and index not in lost:
                end(runs[index].session_id, runs[index].finish().value)


def _between_steps(run: _Run) -> bool:
    """The run's own work between steps; False (and its trainer stopped: it leaves the
    population, the others go on) when another worker took its session back."""
    try:
        run.between_steps()
    except LeaseLost as error:
        log.warning("%s", error)
        run.trainer.stop()
        return False
    return True


def _record_numerics(run: _Run, numerics: dict[str, Any]) -> None:
    """The population's size and layout in the provenance entry this start added."""
    with run.factory() as db:
        row = db.get(StudySession, run.session_id)
        assert row is not None
        entries = list(row.provenance or [])
        entries[-1:] = [{**(entries[-1] if entries else {}), "population": numerics}]
        db.execute(
            update(StudySession)
            .where(StudySession.id == run.session_id, StudySession.worker_token == run.token)
            .values(provenance=entries)
        )
        db.commit()


def _ticker(runs: list[_Run], population: Population) -> Callable[[], None]:
    def tick() -> None:
        for index in population.active:
            runs[index].recorder.tick()

    return tick


def _no_pause(paused: bool, at_step_boundary: bool) -> None:
    """Batch runs are not paused (the runner only shuts its workers down)."""


def _nothing() -> None:
    """Nobody watches a batch run."""


def population_key(run: RunSpec) -> DQNConfig | None:
    """What runs must share to train in one population: the learner configuration as
    stored (pinned numerics included), less what may differ per agent
    (`learner.config.PER_AGENT_FIELDS`); None for a run that trains alone (another learner,
    or a person advising)."""
    if run.learner != "dqn" or run.method == "human":
        return None
    return shared_config(run.config)
