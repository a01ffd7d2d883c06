"""Participants an hour the training queue sustains: how fast its trainer slots train
finished human sessions, alone and in populations (issue 21).

    python -m benchmarks.bench_training_queue                 # populations of 1 and the default
    python -m benchmarks.bench_training_queue --sizes 1 2 --episodes 1 --tiny

A finished human session trains the rest of its run (300 episodes at the paper's scale,
about `PAPER_TRAINING_STEPS` training steps) in one of the server's `max_trainers` slots
(default: one per core), alone or, with `training_population`, together with the queued
sessions of its learner configuration as a population in one worker process. What one
slot then computes is a population of autonomous runs of the same learner: the
participant's advice is over, so nothing else is asked of the advisor.

So the rate is measured on the worker code a slot runs: for each size N, `slots`
populations of N side by side (the batch's local backend, which runs groups of runs with
`run_session` alone and `runs.worker.population.run_population` together, the function
the queue's population worker `population_main` runs), each run the paper's learner
(one torch thread, fast motion, records in a SQLite file) for `--episodes` training
episodes after a short pretraining (a human session pretrains before its advice, in its
own worker, not in a slot: only training steps are counted). Training agent-steps per
second over all slots, from the step records, while every slot was busy (from the last
run's first training step to the first run's last: runs of the same episodes end at
different times, and in a queue with people waiting a slot that frees takes the next at
once, where the batch's last run would train on alone; the rate over the batch's whole
span, that idle tail included, is printed beside it, and was the headline before
2026-12-05 late), extrapolated per agent-step to the paper's `PAPER_TRAINING_STEPS` per
participant: participants an hour = rate x 3600 / PAPER_TRAINING_STEPS. Not counted: a
population's start (each session's worker checkpoints and exits, the population's worker
loads the checkpoints: seconds, against minutes of training), the advising participants'
own share of the cores, and, in short runs, what a paper-scale run's later checkpoints
cost (every `--checkpoint-every` episodes the replay memory is saved whole, about 90 MiB
by a paper-scale run's end): `--episodes 300` measures whole paper-scale runs.

Other processes share the CPUs: the CPU kind and the load average are printed with every
number. The lines also go to a log (`--log`, by default benchmarks/logs/training-queue-*.log).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from benchmarks.bench_population_batch import Log, batch_rate, load, template
from learner import machine
from runs.batch.backends import usable_cores
from runs.worker.population import default_population

LOGS = Path(__file__).parent / "logs"
PAPER_TRAINING_STEPS = 6_700
"""Training steps of a paper-scale session after its advice (300 episodes; issue 19's
measurement of the paper preset, as benchmarks/bench_capacity.py counts them)."""
ARRIVALS_PER_HOUR = 30
"""What issue 21 asks of an online study: thirty participants an hour."""


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_training_queue")
    parser.add_argument(
        "--sizes", type=int, nargs="+", default=None, help="population sizes (default: 1 and "
        "the default rule's, as `training_population=0` gives)"
    )  # fmt: skip
    parser.add_argument("--slots", type=int, default=usable_cores(), help="max_trainers")
    parser.add_argument("--episodes", type=int, default=5, help="training episodes per run")
    parser.add_argument("--pretraining-steps", type=int, default=200)
    parser.add_argument("--checkpoint-every", type=int, default=10)
    parser.add_argument("--tiny", action="store_true", help="a tiny scale: checks it runs")
    stamp = datetime.now(UTC).strftime("%Y-%m-%dT%H%M%SZ")
    parser.add_argument("--log", type=Path, default=LOGS / f"training-queue-{stamp}.log")
    args = parser.parse_args(argv)
    before = os.getloadavg()[0]
    log = Log(args.log)
    run = template(args)
    default = default_population(run.pinned(), workers=args.slots)
    sizes = sorted(set(args.sizes or [1, default]))
    log(f"bench_training_queue {' '.join(argv or [])} at {stamp}")
    log(f"{machine.cpu_kind()}, {usable_cores()} cores; {load()}")
    log(f"runs: {run.config}")
    log(
        f"{args.slots} trainer slots; the default population here: {default}; measured: "
        f"{args.episodes} training episodes per run, extrapolated per agent-step to "
        f"{PAPER_TRAINING_STEPS} training steps per participant (the paper's 300 episodes)"
    )
    if args.tiny:
        log("--tiny: a check that the script runs, not a measurement")
    rates: dict[int, float] = {}
    spans: dict[int, float] = {}
    for size in sizes:
        result = batch_rate(args, size, args.slots)
        rates[size], spans[size] = result["busy"], result["rate"]
        log(
            f"N={size}: {args.slots} x {size} sessions, {result['steps']} training steps, "
            f"{result['busy']:.1f} agent-steps/s in all while every slot was busy "
            f"({result['rate']:.1f} over the batch's whole span, its idle tail included), "
            f"{result['wall']:.0f} s, workers' peak resident memory "
            f"{result['rss'] / 2**20:.0f} MiB; {load()}"
        )
    log(
        f"\nparticipants an hour the training queue sustains ({args.slots} slots, paper scale; "
        "while every slot is busy, as with people waiting: a slot that frees takes the next "
        "at once)"
    )
    for size in sizes:
        per_hour = rates[size] * 3600 / PAPER_TRAINING_STEPS
        minutes = PAPER_TRAINING_STEPS * size / (rates[size] / args.slots) / 60
        verdict = "keeps up with" if per_hour >= ARRIVALS_PER_HOUR else "falls behind"
        log(
            f"  population {size:2}{' (default)' if size == default else ''}: "
            f"{per_hour:5.1f} participants/hour ({rates[size] / rates[sizes[0]]:.2f}x "
            f"population {sizes[0]}; a slot trains {size} in about {minutes:.1f} min); "
            f"{verdict} {ARRIVALS_PER_HOUR} an hour (over the batch's whole span: "
            f"{spans[size] * 3600 / PAPER_TRAINING_STEPS:.1f})"
        )
    log(f"{machine.cpu_kind()}; {load()}")
    # Its own slots make a load of about `slots`: more than one process beyond them (or
    # more than one before it began) is someone else's work.
    if before > 1.0 or os.getloadavg()[0] > args.slots + 1.0:
        log(
            f"the machine was shared (1-minute load {before:.2f} before, above its own "
            f"{args.slots} slots during it): the slots got part of the cores; on a quiet "
            "machine the rates are higher"
        )
    else:
        log(f"quiet: 1-minute load {before:.2f} before it began, its own slots during it")
    log(f"\nlog: {args.log}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
