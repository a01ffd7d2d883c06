"""How long the paper's batch takes on this machine: time a short batch, extrapolate.

Runs `--workers` autonomous agents at the paper's settings (1,000 pretraining steps,
batch 128, memory 20,000) for `--episodes` training episodes through the batch runner
(the same worker processes as `ideeprl batch`), reads the seconds per step of each phase
from the step records, and extrapolates one full run (1,000 pretraining steps and
`--training-steps` training steps, about what a 300-episode run takes: 6,659 for an
autonomous agent with seed 1 on this platform) and the whole batch (`--runs`, the
paper's comparison being 3 methods x 10 agents + the advisor = 31). The machine's load
average is printed beside: on a shared machine, every number here is an upper bound.

    python -m benchmarks.bench_batch [--episodes 10] [--workers 2] [--training-steps 6659]
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from sqlalchemy import select

from learner.run import RunSpec
from runs.batch import BatchSpec, RunnerOptions, run_batch
from runs.batch.backends import usable_cores
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Step, StudySession
from study.services.studies import create_study

PRETRAINING_STEPS = 1000


def per_step_seconds(db_url: str, session_ids: list[int]) -> dict[str, float]:
    """Median over runs of the mean seconds between consecutive steps, by phase; and the
    start-up (claim to first step) and the final checkpoint (last step to finished)."""
    factory = make_session_factory(make_engine(db_url))
    phases: dict[str, list[float]] = {"pretrain": [], "train": [], "startup": [], "final": []}
    with factory() as db:
        for session_id in session_ids:
            rows = db.execute(
                select(Step.stage, Step.wall_time)
                .where(Step.session_id == session_id)
                .order_by(Step.global_step)
            ).all()
            stamps = np.array([w for _, w in rows])
            gaps = np.diff(stamps)
            stage = np.array([p for p, _ in rows[1:]])
            for name in ("pretrain", "train"):
                chosen = gaps[stage == name]
                if len(chosen):
                    phases[name].append(float(chosen.mean()))
            session = db.get(StudySession, session_id)
            assert session is not None and session.started_at and session.finished_at
            phases["startup"].append(stamps[0] - session.started_at.timestamp())
            phases["final"].append(session.finished_at.timestamp() - stamps[-1])
    return {name: float(np.median(values)) for name, values in phases.items() if values}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=10, help="training episodes timed")
    parser.add_argument("--workers", type=int, default=usable_cores(), help="runs at once")
    parser.add_argument(
        "--training-steps", type=int, default=6659, help="training steps of one full run"
    )
    parser.add_argument("--runs", type=int, default=31, help="runs of the whole batch")
    parser.add_argument("--checkpoint-every", type=int, default=50, help="as the batch will run it")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{Path(tmp) / 'bench.sqlite3'}"
        engine = make_engine(url)
        upgrade(engine)
        with make_session_factory(engine)() as db:
            study = create_study(db, "bench").id
        template = RunSpec.from_json({"config": {"episodes": args.episodes, "torch_threads": 1}})
        spec = BatchSpec(template=template, methods=("autonomous",), agents=args.workers)
        load_before = os.getloadavg()[0]
        started = time.perf_counter()
        result = run_batch(
            spec,
            study,
            url,
            RunnerOptions(data_dir=Path(tmp), workers=args.workers, progress=True),
        )
        wall = time.perf_counter() - started
        assert result.complete, [r.detail for r in result.runs]
        seconds = per_step_seconds(url, result.session_ids())
    load_after = os.getloadavg()[0]

    checkpoints = math.ceil(300 / args.checkpoint_every) + 1
    per_run = (
        seconds["startup"]
        + PRETRAINING_STEPS * seconds["pretrain"]
        + args.training_steps * seconds["train"]
        + checkpoints * seconds["final"]
    )
    waves = math.ceil(args.runs / args.workers)
    print(
        f"\n{args.workers} runs at once, {args.episodes} training episodes each, "
        f"{wall:.0f} s in all; load average {load_before:.1f} before, {load_after:.1f} after "
        f"({usable_cores()} cores)"
    )
    print(f"  start-up (claim to first step): {seconds['startup']:8.1f} s")
    print(f"  pretraining step:               {1000 * seconds['pretrain']:8.1f} ms")
    print(f"  training step (with update):    {1000 * seconds['train']:8.1f} ms")
    print(f"  checkpoint (the final one):     {seconds['final']:8.1f} s")
    print(
        f"one full run ({PRETRAINING_STEPS} + {args.training_steps} steps, {checkpoints} "
        f"checkpoints): {per_run / 60:.1f} min"
    )
    print(
        f"the batch ({args.runs} runs, {args.workers} at once, {waves} waves): "
        f"{waves * per_run / 3600:.1f} h"
    )


if __name__ == "__main__":
    main()
