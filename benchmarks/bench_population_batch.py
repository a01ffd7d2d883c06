"""Populations through `ideeprl batch`: agent-steps per second against two runs side by side.

    python -m benchmarks.bench_population_batch                   # sizes 1 2 4 8, 3 repeats
    python -m benchmarks.bench_population_batch --sizes 1 2 --episodes 1 --repeats 1 --tiny

1. For each population size N: a batch of `workers` x N autonomous runs (the paper's
   learner, fast motion, records in a SQLite file) through the batch runner, the same
   worker processes as `ideeprl batch --population N`: `workers` populations of N side by
   side (`workers`: this machine's cores, one torch thread each). N=1 is the reference,
   today's best use of the cores: single runs side by side (two on two cores). The rate is
   training agent-steps per second, from the step records (all training steps of the batch,
   over the time from its first training step to its last), and beside it the batch's
   wall time and its workers' peak resident memory (N separate runs against one
   population of N). The sizes are run in turn, `--repeats` rounds; the ratio to the reference is
   taken within each round (the same machine load) and its median reported.
2. A population step of N agents split into its parts, in this process, through the batch's
   own population worker (`runs.worker.population.run_population`, recording to SQLite
   and checkpointing as a batch does): the update, action selection (one batched forward
   pass), simulation (the environments' steps less their rendering), rendering (the 64x64
   camera image), recording (step and episode rows, their inserts), checkpointing (the
   checkpoint files; their flush is recording), and the rest.

Other processes share the CPUs: compare ratios, not times; the CPU kind and the load
average are recorded with every number. Pause background batches while it runs. Each run
appends its lines to a log (`--log`, by default benchmarks/results/population-batch-*.log).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select

from learner import machine
from learner.run import RunSpec
from runs.batch import BatchSpec, RunnerOptions, run_batch
from runs.batch.backends import usable_cores
from runs.batch.runner import BatchRunner
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Step
from study.services.studies import create_study

RESULTS = Path(__file__).parent / "results"
PARTS = (
    "update", "action selection", "simulation", "rendering", "recording", "checkpointing",
)  # fmt: skip


class Log:
    """Prints and appends to the run's log file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)

    def __call__(self, line: str = "") -> None:
        print(line, flush=True)
        with self.path.open("a") as f:
            f.write(line + "\n")


def load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def template(args: argparse.Namespace) -> RunSpec:
    """The runs timed: the paper's learner at the scale asked, one torch thread, fast motion."""
    config: dict[str, Any] = {
        "episodes": args.episodes,
        "torch_threads": 1,
        "pretraining_steps": args.pretraining_steps,
    }
    if args.tiny:  # checks that the script works, in seconds: no number to keep
        config |= {"batch_size": 8, "memory_size": 300, "max_episode_steps": 20}
    return RunSpec.from_json({"config": config, "motion": "fast"})


def fresh_study(url: str, name: str) -> int:
    engine = make_engine(url)
    upgrade(engine)
    with make_session_factory(engine)() as db:
        return create_study(db, name).id


def training_rate(url: str, session_ids: list[int]) -> tuple[int, float]:
    """Training steps of the sessions, and the seconds from their first to their last."""
    with make_session_factory(make_engine(url))() as db:
        stamps = db.scalars(
            select(Step.wall_time).where(Step.session_id.in_(session_ids), Step.stage == "train")
        ).all()
    return len(stamps), float(max(stamps) - min(stamps)) if stamps else 0.0


def busy_rate(url: str, session_ids: list[int]) -> tuple[int, float]:
    """Training steps, and seconds, while every one of the sessions trained: from the last
    of their first training steps to the first of their last. Runs of the same episodes end
    at different times (their episodes differ in length), and after the first ends its slot
    would, in a queue with people waiting, take the next one at once: the batch's whole
    span (`training_rate`) counts that idle tail against the slots."""
    with make_session_factory(make_engine(url))() as db:
        rows = db.execute(
            select(Step.session_id, Step.wall_time).where(
                Step.session_id.in_(session_ids), Step.stage == "train"
            )
        ).all()
    spans: dict[int, list[float]] = {}
    for session_id, stamp in rows:
        spans.setdefault(session_id, []).append(float(stamp))
    if len(spans) < len(session_ids):
        return 0, 0.0
    start = max(min(stamps) for stamps in spans.values())
    end = min(max(stamps) for stamps in spans.values())
    steps = sum(start < t <= end for stamps in spans.values() for t in stamps)
    return steps, max(end - start, 0.0)


def children_rss(parent: int) -> int:
    """Resident bytes of `parent`'s child processes (the batch's workers), from /proc."""
    total = 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rpartition(")")[2].split()
            if int(fields[1]) == parent:
                total += int(fields[21]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError, IndexError):
            continue
    return total


class PeakMemory:
    """The peak of the workers' summed resident memory, sampled on a thread while a batch
    runs (each run's process, or each population's: what N separate runs cost against one
    population of N)."""

    def __init__(self, every_s: float = 0.5) -> None:
        self.peak = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, args=(every_s,), daemon=True)

    def _sample(self, every_s: float) -> None:
        while not self._stop.wait(every_s):
            self.peak = max(self.peak, children_rss(os.getpid()))

    def __enter__(self) -> PeakMemory:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def batch_rate(args: argparse.Namespace, size: int, workers: int) -> dict[str, float]:
    """One batch of `workers` x `size` runs, populations of `size`: its training
    agent-steps per second, its wall time and its workers' peak resident memory."""
    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{Path(tmp) / 'bench.sqlite3'}"
        study = fresh_study(url, "bench")
        spec = BatchSpec(template=template(args), methods=("autonomous",), agents=workers * size)
        options = RunnerOptions(
            data_dir=Path(tmp),
            workers=workers,
            population=size,
            progress=False,
            checkpoint_every_episodes=args.checkpoint_every,
        )
        started = time.perf_counter()
        with PeakMemory() as memory:
            result = run_batch(spec, study, url, options)
        wall = time.perf_counter() - started
        assert result.complete, [r.detail for r in result.runs]
        steps, seconds = training_rate(url, result.session_ids())
        busy_steps, busy_seconds = busy_rate(url, result.session_ids())
    rate = steps / seconds if seconds else float("nan")
    busy = busy_steps / busy_seconds if busy_seconds else float("nan")
    return {"rate": rate, "busy": busy, "wall": wall, "steps": steps, "rss": memory.peak}


class _Timed:
    """Adds the wall time of a method's calls to `totals[name]`; a call inside another call
    timed under the same name is not counted twice (a record's flush inside its on_episode)."""

    def __init__(self, totals: dict[str, float], name: str, function: Callable) -> None:
        self.totals, self.name, self.function = totals, name, function

    def __get__(self, obj: Any, owner: Any = None) -> Callable:
        def bound(*args: Any, **kwargs: Any) -> Any:
            if _running.get(self.name):
                return self.function(obj, *args, **kwargs)
            _running[self.name] = True
            start = time.perf_counter()
            try:
                return self.function(obj, *args, **kwargs)
            finally:
                self.totals[self.name] += time.perf_counter() - start
                _running[self.name] = False

        return bound


_running: dict[str, bool] = {}


def profile(args: argparse.Namespace, size: int) -> dict[str, float]:
    """Milliseconds per agent-step by part, for one population of `size` run as a batch's
    worker runs it, here (its own process: the parts are timed by wrapping their methods)."""
    import sim
    from learner.population import Population
    from runs.worker.population import AgentSaver, run_population
    from runs.worker.recorder import Recorder
    from runs.worker.worker import WorkerOptions

    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{Path(tmp) / 'bench.sqlite3'}"
        study = fresh_study(url, "profile")
        spec = BatchSpec(template=template(args), methods=("autonomous",), agents=size)
        options = RunnerOptions(data_dir=Path(tmp), progress=False)
        runner = BatchRunner(spec, study, url, options)
        runner.log = lambda line: None
        runner.prepare()
        ids = [s.session_id for s in runner.states if s.session_id is not None]
        totals = dict.fromkeys(PARTS, 0.0)
        patches = {
            (Population, "_update"): "update",
            (Population, "_q_values"): "action selection",
            (sim.SortingEnv, "step"): "simulation",
            (sim.SortingEnv, "reset"): "simulation",
            (type_of_camera(), "image"): "rendering",
            (Recorder, "on_step"): "recording",
            (Recorder, "on_episode"): "recording",
            (Recorder, "flush"): "recording",
            (AgentSaver, "save_checkpoint"): "checkpointing",
        }
        originals = {key: getattr(*key) for key in patches}
        try:
            for (owner, name), part in patches.items():
                setattr(owner, name, _Timed(totals, part, originals[(owner, name)]))
            worker = WorkerOptions(
                data_dir=Path(tmp), checkpoint_every_episodes=args.checkpoint_every
            )
            started = time.perf_counter()
            statuses = run_population(ids, runner.database_url, worker)
            total = time.perf_counter() - started
        finally:
            for (owner, name), original in originals.items():
                setattr(owner, name, original)
        assert set(statuses.values()) == {"finished"}, statuses
        steps, _ = training_rate(runner.database_url, ids)
        with make_session_factory(make_engine(runner.database_url))() as db:
            all_steps = len(db.scalars(select(Step.id).where(Step.session_id.in_(ids))).all())
    totals["simulation"] -= totals["rendering"]  # a step (and a reset) renders
    totals["rest"] = total - sum(totals[p] for p in PARTS)
    result = {name: 1000 * seconds / all_steps for name, seconds in totals.items()}
    return result | {"total": 1000 * total / all_steps, "training steps": steps}


def type_of_camera() -> type:
    from sim.camera import Camera

    return Camera


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_population_batch")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--workers", type=int, default=usable_cores(), help="side by side")
    parser.add_argument("--episodes", type=int, default=5, help="training episodes per run")
    parser.add_argument("--pretraining-steps", type=int, default=1000)
    parser.add_argument("--checkpoint-every", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3, help="rounds over the sizes")
    parser.add_argument("--profile-sizes", type=int, nargs="+", default=[1, 8])
    parser.add_argument("--tiny", action="store_true", help="a tiny scale: checks it runs")
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    parser.add_argument("--log", type=Path, default=RESULTS / f"population-batch-{stamp}.log")
    args = parser.parse_args(argv)
    log = Log(args.log)
    log(f"bench_population_batch {' '.join(argv or [])} at {stamp}")
    log(f"{machine.cpu_kind()}, {usable_cores()} cores; {load()}")
    log(f"runs: {template(args).config}")
    sizes = sorted(set(args.sizes) | {1})
    rounds: dict[int, list[dict[str, float]]] = {n: [] for n in sizes}
    for r in range(args.repeats):
        for size in sizes:
            result = batch_rate(args, size, args.workers)
            rounds[size].append(result)
            log(
                f"round {r + 1}, N={size}: {args.workers} x {size} runs, {result['steps']} "
                f"training steps, {result['rate']:.1f} agent-steps/s, batch {result['wall']:.0f} s"
                f", workers' peak resident memory {result['rss'] / 2**20:.0f} MiB; {load()}"
            )
    log(
        f"\ntraining agent-steps per second, {args.workers} populations of N side by side "
        f"(median of {args.repeats}; x: against N=1, {args.workers} single runs side by side, "
        "per round)"
    )
    for size in sizes:
        ratios = [r["rate"] / ref["rate"] for r, ref in zip(rounds[size], rounds[1], strict=True)]
        rate = statistics.median(r["rate"] for r in rounds[size])
        wall = statistics.median(r["wall"] for r in rounds[size])
        rss = statistics.median(r["rss"] for r in rounds[size]) / 2**20
        log(
            f"  N={size:2}: {rate:7.1f} agent-steps/s  {statistics.median(ratios):5.2f}x  "
            f"(batch of {args.workers * size} runs: {wall:.0f} s; workers' peak resident "
            f"memory {rss:.0f} MiB, {rss / (args.workers * size):.0f} MiB per agent)"
        )
    log("\na population step by part (ms per agent-step, over the whole run; one process)")
    for size in args.profile_sizes:
        parts = profile(args, size)
        line = ", ".join(f"{k} {v:.2f}" for k, v in parts.items() if k != "training steps")
        log(f"  N={size:2}: {line}; {load()}")
    log(f"\nlog: {args.log}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
