"""The population benchmark's logs as one figure, a CPU kind a line.

    python -m benchmarks.plot_population_batch \
        benchmarks/logs/population-batch-2026-12-03-quiet.log \
        benchmarks/logs/population-batch-2026-12-04-avx2-quiet.log \
        benchmarks/logs/population-batch-2026-12-04-avx2-padded.log

Reads what `benchmarks/bench_population_batch.py` wrote (its CPU kind line, its summary of
training agent-steps per second and memory per agent, and its profile of a step by part)
and draws, against the population size N: the rate relative to two single runs, the
resident memory per agent, and one agent-step split into its parts. Writes
docs/images/population_batch.png (and .svg).
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence
from pathlib import Path

OUT = Path("docs/images/population_batch.png")
KIND = re.compile(r"^(?P<kind>.+), \d+ cores; load average")
RATE = re.compile(
    r"^\s+N=\s*(?P<n>\d+):\s+(?P<rate>[\d.]+) agent-steps/s\s+(?P<ratio>[\d.]+)x.*?"
    r"(?P<mib>\d+) MiB per agent\)"
)
PART = re.compile(r"^\s+N=\s*(?P<n>\d+): (?P<parts>update .*?), total (?P<total>[\d.]+);")


def read_log(path: Path) -> dict:
    """The CPU kind, {N: (rate, ratio, MiB per agent)} and {N: {part: ms}} of one log."""
    kind, rates, parts = "", {}, {}
    for line in path.read_text().splitlines():
        if not kind and (match := KIND.match(line)):
            kind = match["kind"]
        elif match := RATE.match(line):
            rates[int(match["n"])] = (
                float(match["rate"]),
                float(match["ratio"]),
                int(match["mib"]),
            )
        elif match := PART.match(line):
            split = (item.rsplit(" ", 1) for item in match["parts"].split(", "))
            parts[int(match["n"])] = {name: float(ms) for name, ms in split}
    if not rates:
        raise SystemExit(f"{path}: no summary lines of bench_population_batch")
    return {"kind": kind, "name": path.stem.removeprefix("population-batch-"), "rates": rates,
            "parts": parts}  # fmt: skip


def plot(logs: Sequence[Path], out: Path = OUT) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [read_log(path) for path in logs]
    fig, axes = plt.subplots(1, 2 + len(runs), figsize=(5 * (2 + len(runs)), 4.2))
    for run in runs:
        sizes = sorted(run["rates"])
        label = f"{run['kind']} ({run['name']})"
        rate = [run["rates"][n][0] for n in sizes]
        axes[0].plot(sizes, rate, "o-", label=label)
        axes[1].plot(sizes, [run["rates"][n][2] for n in sizes], "o-", label=label)
    axes[0].set_title("training agent-steps/s, 2 workers of N agents")
    axes[0].set_xlabel("population size N")
    axes[0].set_ylim(bottom=0)
    axes[0].legend(fontsize=8)
    axes[1].set_title("peak resident memory per agent (MiB)")
    axes[1].set_xlabel("population size N")
    axes[1].set_ylim(bottom=0)
    for ax in axes[:2]:
        ax.set_xscale("log", base=2)
        ax.set_xticks(sorted({n for run in runs for n in run["rates"]}))
        ax.get_xaxis().set_major_formatter(matplotlib.ticker.ScalarFormatter())
    for ax, run in zip(axes[2:], runs, strict=True):
        sizes = sorted(run["parts"])
        names = list(next(iter(run["parts"].values())))
        bottom = [0.0] * len(sizes)
        for name in names:
            values = [run["parts"][n].get(name, 0.0) for n in sizes]
            ax.bar([str(n) for n in sizes], values, bottom=bottom, label=name)
            bottom = [b + v for b, v in zip(bottom, values, strict=True)]
        ax.set_title(f"one agent-step by part (ms)\n{run['kind']} ({run['name']})", fontsize=9)
        ax.set_xlabel("population size N (one process)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    fig.savefig(out.with_suffix(".svg"))
    return out


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.plot_population_batch")
    parser.add_argument("logs", type=Path, nargs="+")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    print(plot(args.logs, args.out))


if __name__ == "__main__":
    main()
