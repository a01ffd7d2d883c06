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
`interrupted`; a stop naming one session (`Command("stop", session_id=...)`) stops
that agent alone, the others go on.

The web process trains finished human sessions this way too (`population_main`): their
own workers hand them over at a checkpoint, still `running` under their tokens, and each
session's messages (progress, episodes, status) go to the web process over the
population's channel `Tagged` with it, as its own worker sent them.

Who trains together is decided by one rule for the batch and the web process's training
queue: `population_key` (one learner configuration), `next_group` (the first waiting run
and those that can join it, spread over the free workers) and `default_population` (how
many at most). An error in a step fails every agent still training (each resumes from its
last checkpoint when the batch runs again): the agents' steps are interleaved, so no agent
can be told apart as the one at fault.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from sqlalchemy import update

from learner import machine
from learner.config import DQNConfig, shared_config
from learner.run import PROCESS_BYTES, RunSpec, declare
from runs.worker.link import StopRequested, TaggedChannel, WorkerExit, WorkerLink
from runs.worker.priority import lower_priority
from runs.worker.recorder import LeaseLost
from runs.worker.worker import WorkerOptions, _Run, claim_session, fail_session
from study.db.engine import make_engine, make_session_factory
from study.db.models import Status, StudySession

if TYPE_CHECKING:
    from learner.population import Population, PopulationNumerics

log = logging.getLogger(__name__)
NOT_RUN = "not run: "
"""How a worker reports a session it could not claim (another runner has it)."""
T = TypeVar("T")


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
    tokens: Mapping[int, str] | None = None,
) -> dict[int, str]:
    """Run the sessions to their end together in this process; returns each one's final
    status (as `run_session` gives it, `NOT_RUN` and why for one it could not claim), and
    calls `ended(session_id, status)` as each ends (an agent that finishes early is
    reported at once).

    `tokens`: sessions already running under these worker tokens, handed over by their own
    workers (the web process's training queue): they are not claimed again, and each tells
    `conn` what its own worker told it, `Tagged` with its session."""
    if options.nice:
        lower_priority(options.nice, idle=options.idle)
    with declare(options.declaration):
        return _run_together(session_ids, database_url, options, conn, ended, tokens)


def _run_together(
    session_ids: Sequence[int],
    database_url: str,
    options: WorkerOptions,
    conn: Connection | None,
    ended: Callable[[int, str], None],
    tokens: Mapping[int, str] | None,
) -> dict[int, str]:
    factory = make_session_factory(make_engine(database_url))
    statuses: dict[int, str] = {}

    def end(session_id: int, status: str) -> None:
        statuses[session_id] = status
        ended(session_id, status)

    runs: list[_Run] = []
    for session_id in session_ids:
        channel = TaggedChannel(conn, session_id) if tokens is not None and conn else None
        spec = None
        if tokens is not None:
            token = tokens[session_id]
        else:
            try:
                token, spec = claim_session(factory, session_id, options)
            except Exception as error:  # someone else runs it, or it is gone
                end(session_id, f"{NOT_RUN}{error}")
                continue
        try:
            from learner.trainer import Trainer  # torch: loaded in the worker, not the runner

            run = _Run(session_id, database_url, options, token, channel, spec)
            if not isinstance(run.trainer, Trainer):
                raise ValueError(f"session {session_id}'s learner cannot join a population")
            if run.link is not None:
                run.link.may_train = True  # the population is its trainer slot
            runs.append(run)
        except LeaseLost as error:
            log.warning("%s", error)
            end(session_id, "lost")
        except Exception as error:
            fail_session(factory, session_id, token, error, channel)
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
            fail_session(run.factory, run.session_id, run.token, error, _channel(run))
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
                fail_session(run.factory, run.session_id, run.token, error, _channel(run))
                end(run.session_id, Status.failed.value)
    finally:
        population.close()


def _step_until_done(
    population: Population,
    runs: list[_Run],
    conn: Connection | None,
    end: Callable[[int, str], None],
) -> None:
    link = (
        WorkerLink(
            conn,
            _no_pause,
            _nothing,
            _ticker(runs, population),
            on_session_watch=_watcher(runs, population),
        )
        if conn
        else None
    )
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
            one = exit_.session_id if isinstance(exit_, StopRequested) else None
            for index in population.active:
                if one is None or runs[index].session_id == one:
                    end(runs[index].session_id, runs[index].exit(exit_, True).value)
                    runs[index].trainer.stop()  # it leaves the population
                    lost.add(index)
            if one is None:
                return
            continue
        if population.done:
            return
        population.step()
        for index in active:
            if runs[index].trainer.done and index not in lost:
                end(runs[index].session_id, runs[index].finish().value)


def _channel(run: _Run) -> TaggedChannel | None:
    """The run's end of the population's channel, if it reports over one."""
    conn = getattr(run.link, "_conn", None)
    return conn if isinstance(conn, TaggedChannel) else None


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


def _record_numerics(run: _Run, numerics: PopulationNumerics) -> None:
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


def _watcher(runs: list[_Run], population: Population) -> Callable[[int, bool], None]:
    """A viewer arrived at (or left) one session's page: that session's scene goes to it
    from its next step, and all of the scene at once now (between steps)."""

    def watch(session_id: int, watched: bool) -> None:
        for index in population.active:
            run = runs[index]
            if run.session_id == session_id and run.link is not None:
                run.link.watching = watched
                if watched:
                    run.env.announce()

    return watch


def _no_pause(paused: bool, at_step_boundary: bool) -> None:
    """Batch runs are not paused (the runner only shuts its workers down)."""


def _nothing() -> None:
    """A viewer not named for one session: a population passes viewers on by session
    (`_watcher`), and nobody watches a batch run."""


def population_key(run: RunSpec, advice_over: bool = False) -> DQNConfig | None:
    """What runs must share to train in one population: the learner configuration as
    stored (pinned numerics included), less what may differ per agent
    (`learner.config.PER_AGENT_FIELDS`); None for a run that trains alone (another learner,
    or a person advising). `advice_over`: a human session whose participant has finished
    advising trains on like any other run."""
    if run.learner != "dqn" or (run.method == "human" and not advice_over):
        return None
    return shared_config(run.config)


def next_group(
    queue: Sequence[T], keys: Sequence[Hashable | None], population: int, workers: int
) -> list[T]:
    """The runs to start next from a non-empty `queue` (oldest first), whose population
    keys are `keys` (None: alone): the first and the waiting runs that can train with it
    (the same key), at most `population`, and no more than spreads them evenly over
    `workers`: the workers free now and those that were busy when they freed (ten runs
    when one of two workers frees go as five now and five for the other, so the other
    does not idle when it frees; four runs on two free workers go as two and two)."""
    if len(keys) != len(queue):
        raise ValueError(f"{len(keys)} keys for {len(queue)} runs")
    mine = keys[0]
    mates = [queue[0]]
    if mine is not None and population > 1:
        mates = [item for item, key in zip(queue, keys, strict=True) if key == mine]
    return mates[: max(1, min(population, -(-len(mates) // max(1, workers))))]


POPULATION_CUDA = 16
POPULATION_CPU = 2
MEMORY_SHARE = 0.8
"""Of the machine's memory, what a batch's populations may fill with their agents."""


def default_population(run: RunSpec, cores: int | None = None, workers: int | None = None) -> int:
    """How many runs a worker trains together when the batch leaves it open, by a simple
    rule: 16 on CUDA, 2 on a CPU; and no more than the memory holds when each of the
    `workers` (default: cores / torch threads) trains a population of the run's size
    (`RunSpec.memory_needed`, `MEMORY_SHARE` of the memory).

    On a CPU each agent's update is 88 % of its step and stays its own (the same kernels on
    the same shapes as alone), so a population shares only the rest: measured on a quiet
    2-core EPYC with AVX-512 BF16 (`benchmarks/bench_population_batch.py`, log
    `benchmarks/logs/population-batch-2026-12-03-quiet.log`), two populations side by side
    against two single runs: N=2 1.06x, N=4 1.04x, N=8 0.90x, N=16 0.93x, while the
    resident memory per agent falls from 522 MiB to 282 (N=2) and 106 (N=8). On a loaded
    machine larger populations looked faster (1.59x at N=8 with the load at 4-6): that was
    the single runs losing more to the load, not the populations gaining. Without AVX-512
    BF16 the update is a larger share still (95 % of a step, float32) and the rule the same:
    on the quiet AVX2-only EPYC (log `population-batch-2026-12-04-avx2-quiet.log`) N=2 and
    N=4 both 1.13x, the memory per agent 555, 298 and 173 MiB; with the padded update
    (`population-batch-2026-12-04-avx2-padded.log`, the rates 1.38-1.57x the unpadded ones) N=2
    1.08x, N=4 0.99x.

    On CUDA the update leaves the critical path, and the population's size only has to
    fill the GPU: measured once, on a lent H200 beside a 16-core Xeon
    (`docs/results/cuda-2026-12-04/`), a population of 10 took 5.96 ms per agent-step, of
    which the update 1.07 and rendering the camera image on the CPU 2.98; four workers'
    populations used 7.9 GiB of the GPU's memory. There the CPU's cores bound the rate, so
    the workers default to one per core as on a CPU."""
    config = run.config
    size = POPULATION_CUDA if config.device.startswith("cuda") else POPULATION_CPU
    workers = workers or max(1, (cores or machine.usable_cores()) // max(1, config.torch_threads))
    total = machine.total_memory()
    if total:  # one process's torch and simulator per worker, a replay memory per agent
        agent = run.memory_needed() - PROCESS_BYTES
        size = min(size, int((total * MEMORY_SHARE / workers - PROCESS_BYTES) / agent))
    return max(1, size)


def population_main(
    session_ids: Sequence[int],
    tokens: Mapping[int, str],
    database_url: str,
    options: WorkerOptions,
    conn: Connection,
) -> None:
    """Entry point of the web process's population worker: trains sessions its training
    queue granted a slot together, each handed over by its own worker at a checkpoint
    (`server.live.manager`)."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s population %(process)d %(message)s")
    try:
        run_population(session_ids, database_url, options, conn, tokens=tokens)
    finally:
        conn.close()
