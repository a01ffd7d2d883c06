"""Resident memory of a population of agents at the end of a paper-scale run, against the
same agents as separate runs.

    python -m benchmarks.bench_population_memory                    # 10 agents, 7,700 transitions
    python -m benchmarks.bench_population_memory --agents 10 --transitions 20000

Each measurement runs in a fresh process (`python -m benchmarks.bench_population_memory
--child N`), so nothing of another is counted: it builds a population of N agents of the
`paper` preset (`learner.population`, each with its own fast-motion environment, network,
RMSprop state and replay memory), steps it past pretraining into training, fills every
replay memory up to `--transitions` with real observations (a paper-scale run of 300
episodes ends with about 7,700: 1,000 pretraining and about 6,700 training steps; the
memory's capacity is 20,000), takes `--steps` more population steps so that updates and
action selection have made their working buffers, and reports its resident memory (RSS)
and proportional set size (PSS) from `/proc/self/smaps_rollup`. Separate runs are N
processes of one agent each; they share nothing but the libraries' code pages, so their
total is N times one (measured once, at N=1). Memory does not depend on what the frames
show or on the values learned, so filling the memories directly gives the end of a run's
footprint in about a minute instead of the run's half hour. A real batch worker also
holds its database connection and records (`ideeprl batch`); the replication's memory
logs measure those beside this.

Writes the numbers to stdout, a log under `benchmarks/logs/` and a bar chart to
`docs/images/population_memory.png`.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

LOG_DIR = Path("benchmarks/logs")
PLOT = Path("docs/images/population_memory.png")


def _memory() -> dict[str, float]:
    """This process's RSS and PSS, MiB."""
    fields = {}
    with open("/proc/self/smaps_rollup") as rollup:
        for line in rollup:
            key, _, value = line.partition(":")
            if key in ("Rss", "Pss"):
                fields[key.lower()] = int(value.split()[0]) / 1024
    return fields


def child(agents: int, transitions: int, steps: int) -> dict:
    import numpy as np
    import torch

    import sim
    from benchmarks.bench_learner import BATCH, real_frames
    from learner.config import DQNConfig
    from learner.population import Member, Population

    torch.set_num_threads(1)
    start = time.perf_counter()
    stages = {"imports": _memory()}
    config = DQNConfig.preset("paper")
    config = config.replace(pretraining_steps=BATCH)
    members = [Member(sim.SortingEnv(motion="fast"), seed) for seed in range(agents)]
    population = Population(config, members)
    stages["built"] = _memory()
    while any(t.stage == "pretrain" for t in population.trainers):
        population.step()
    frames = real_frames(500)
    rng = np.random.default_rng(0)
    for trainer in population.trainers:
        memory, agent = trainer.memory, trainer.agent
        packed = [agent.encode(frame) for frame in frames]
        while len(memory) < min(transitions, memory.capacity):
            t = memory.added
            done = t % 26 == 25  # about 26 steps an episode, as in the paper's runs
            memory.add(packed[t % 499], int(rng.integers(4)), 0.0, packed[t % 499 + 1], done, False)
    stages["memories filled"] = _memory()
    for _ in range(steps):
        population.step()
    stages["after training steps"] = _memory()
    population.close()
    return {
        "agents": agents,
        "transitions": transitions,
        "replay_mib_per_agent": population.trainers[0].memory.nbytes / 2**20
        if population.trainers
        else 0.0,
        "stages": stages,
        "seconds": time.perf_counter() - start,
    }


def _measure(agents: int, transitions: int, steps: int) -> dict:
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_population_memory", "--child", str(agents),
         "--transitions", str(transitions), "--steps", str(steps)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def _plot(alone: dict, together: dict, agents: int, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    single = alone["stages"]["after training steps"]["rss"]
    population = together["stages"]["after training steps"]["rss"]
    fig, ax = plt.subplots(figsize=(6, 3.2))
    bars = ax.barh(
        [f"{agents} separate runs", f"one population of {agents}"],
        [agents * single / 1024, population / 1024],
        color=["#999999", "#1f77b4"],
    )
    for bar in bars:
        ax.text(bar.get_width(), bar.get_y() + bar.get_height() / 2,
                f" {bar.get_width():.2f} GiB", va="center")  # fmt: skip
    ax.set_xlabel("resident memory at the end of a paper-scale run (GiB)")
    ax.set_xlim(0, agents * single / 1024 * 1.25)
    ax.set_title(f"{agents} agents, {together['transitions']:,} transitions each", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--agents", type=int, default=10)
    parser.add_argument("--transitions", type=int, default=7_700)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--plot", type=Path, default=PLOT)
    args = parser.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(args.child, args.transitions, args.steps)))
        return
    from benchmarks.bench_population import cpu_kind, load

    header = f"{cpu_kind()}; {load()} at start"
    print(header, flush=True)
    alone = _measure(1, args.transitions, args.steps)
    together = _measure(args.agents, args.transitions, args.steps)
    single = alone["stages"]["after training steps"]
    population = together["stages"]["after training steps"]
    lines = [
        header,
        f"paper preset, {args.transitions:,} transitions an agent "
        f"({alone['replay_mib_per_agent']:.0f} MiB of replay memory, allocated for 20,000), "
        f"{args.steps} training steps after the fill",
        f"one run alone: RSS {single['rss']:.0f} MiB, PSS {single['pss']:.0f} MiB "
        f"(imports {alone['stages']['imports']['rss']:.0f} MiB)",
        f"{args.agents} separate runs: RSS {args.agents * single['rss']:.0f} MiB "
        f"({args.agents} x one)",
        f"one population of {args.agents}: RSS {population['rss']:.0f} MiB, "
        f"PSS {population['pss']:.0f} MiB: {population['rss'] / args.agents:.0f} MiB an agent, "
        f"{args.agents * single['rss'] / population['rss']:.2f}x less than separate runs",
        f"{load()} at end",
        "stages (MiB): " + json.dumps({"alone": alone["stages"], "population": together["stages"]}),
    ]
    text = "\n".join(lines)
    print("\n".join(lines[1:]))
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    log = LOG_DIR / f"population-memory-{time.strftime('%Y-%m-%dT%H%M%SZ', time.gmtime())}.log"
    log.write_text(text + "\n")
    _plot(alone, together, args.agents, args.plot)
    print(f"log {log}, plot {args.plot}")


if __name__ == "__main__":
    main()
