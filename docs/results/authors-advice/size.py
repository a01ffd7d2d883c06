"""The numbers of the `authors`-advice study's plan (plan.md), from replication 2's saved
state alone: how many pairs it needs, what its two looks decide, and its compute on each
CPU kind.

    cd docs/results/authors-advice && ../../../.venv/bin/python size.py > size.md

Reads `../replication-2/state/` through replication 2's own `recompute.py` (the same R_T,
the same pairing by seed), so the spread is the one its write-up reports:
- the spread: the SD of the paired R_T differences of comparison 1 (A-agent minus
  A-procedure, the `authors` learner, advised by the `paper` advisor), on every seed both
  arms finished; the margins are 3 % and 2 % of A-procedure's mean over those seeds;
- the pairs: the smallest number at which the test reaches 80 % power (the t distribution,
  the SD taken as known), and again at the SD's 80 % upper confidence bound;
- the two looks (plan.md: 40 and 80 pairs, each at Pocock's 0.0294): each look's power
  alone, and the whole design simulated (normal paired differences with that SD; 20,000
  studies a true difference, a fixed seed): how often it finds an effect, finds
  equivalence within ±3 %, or ends inconclusive;
- the compute: the wall time (started to finished) of every finished `authors` run that ran
  alone and was never resumed, per CPU kind, and what the study's runs take at the median
  and at the fastest of them. A run's wall time includes the load of whatever else ran on
  the machine, so the median is what a shared machine gives and the fastest what a quiet
  core gives.
"""

from __future__ import annotations

import sqlite3
import sys
import tempfile
from datetime import datetime
from pathlib import Path

import numpy as np
from scipy import stats

HERE = Path(__file__).resolve().parent
REPLICATION = HERE.parent / "replication-2"
sys.path.insert(0, str(REPLICATION))
from recompute import (  # noqa: E402
    Data,
    compare,
    detect_power,
    pairs_for_tost,
    pairs_to_detect,
    short_cpu,
    tost_power,
)
from state import merge  # noqa: E402

LOOKS = (40, 80)
"""Pairs at the first and the second look (plan.md)."""
ALPHA = 0.0294
"""Pocock's nominal level at each of two equally spaced looks, for an overall 0.05."""
ALONE = ("A-agent", "A-procedure", "A-auto-amx", "A-auto-alone", "A-auto-fp32")
"""The `authors` arms whose runs ran alone (one agent a process, not a population)."""
STAGE_RUNS = {"stage 1 (agent, procedure)": 80, "its auto arm": 40, "stage 2": 80}
BUDGET_HOURS = 18
"""Issue 48: the study is run at once only if it fits in about this much bfloat16 compute."""
SIMULATED = 20_000
KINDS = {  # recompute.short_cpu's names, in full, in the order the plan lists them
    "Xeon AMX": "Intel Xeon with AVX-512 BF16 and AMX",
    "EPYC BF16": "AMD EPYC with AVX-512 BF16",
    "EPYC AVX2": "AMD EPYC, AVX2 only",
}


def simulate(sd: float, margin: float, truth: float, rng: np.random.Generator) -> dict:
    """The two-look design's outcomes over `SIMULATED` studies with a true mean `truth`."""
    d = rng.normal(truth, sd, size=(SIMULATED, LOOKS[-1]))
    decided = np.zeros(SIMULATED, dtype=bool)
    out = {"effect": 0.0, "equivalent": 0.0, "at first look": 0.0}
    for look in LOOKS:
        x = d[:, :look]
        mean, se = x.mean(axis=1), x.std(axis=1, ddof=1) / np.sqrt(look)
        p = 2 * stats.t.sf(np.abs(mean / se), look - 1)
        t = stats.t.ppf(1 - ALPHA, look - 1)
        effect = ~decided & (p < ALPHA)
        equivalent = ~decided & ~effect & (mean - t * se > -margin) & (mean + t * se < margin)
        out["effect"] += effect.mean()
        out["equivalent"] += equivalent.mean()
        if look == LOOKS[0]:
            out["at first look"] = (effect | equivalent).mean()
        decided |= effect | equivalent
    out["inconclusive"] = 1 - decided.mean()
    return out


def run_minutes(data: Data) -> dict[str, list[float]]:
    """Wall minutes of every finished, never-resumed `authors` run alone, by CPU kind."""
    minutes: dict[str, list[float]] = {}
    for name in ALONE:
        for s in data.arm(name).values():
            if len(s["provenance"]) > 1:
                continue
            took = datetime.fromisoformat(s["finished"]) - datetime.fromisoformat(s["started"])
            kind = short_cpu(s["provenance"][0]["cpu"])
            minutes.setdefault(kind, []).append(took.total_seconds() / 60)
    return minutes


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "state.sqlite3"
        merge(REPLICATION / "state", path)
        data = Data(sqlite3.connect(path))
        c1 = compare(data, "A-procedure", "A-agent", "comparison 1")
        minutes = run_minutes(data)
    n, sd, ref = c1["n"], c1["sd_diff"], c1["mean_first"]
    m3, e2 = 0.03 * ref, 0.02 * ref
    sd_high = sd * np.sqrt((n - 1) / stats.chi2.ppf(0.2, n - 1))
    print("# The `authors`-advice study's size and compute, from replication 2's saved state\n")
    print("Written by [size.py](size.py); do not edit by hand. The plan: [plan.md](plan.md).\n")
    print("## The spread\n")
    print(
        f"- Comparison 1 (A-agent against A-procedure), {n} pairs: difference "
        f"{c1['diff']:+.2f} ({c1['pct']:+.2f} %), 95 % interval [{c1['lo']:+.2f}, "
        f"{c1['hi']:+.2f}], paired p = {c1['p']:.3f}.\n"
        f"- SD of the paired differences {sd:.2f}; its 80 % upper confidence bound "
        f"{sd_high:.2f}. A-procedure's mean {ref:.2f}: ±3 % is ±{m3:.2f}, +2 % is {e2:.2f}.\n"
    )
    print("## Pairs needed (80 % power, one look)\n")
    print(f"| question | test | pairs at SD {sd:.2f} | pairs at SD {sd_high:.2f} |")
    print("|---|---|---:|---:|")
    print(
        f"| the difference within ±3 % (true difference 0) | two one-sided tests, α = 0.05 "
        f"each | **{pairs_for_tost(sd, m3)}** | {pairs_for_tost(sd_high, m3)} |"
    )
    print(
        f"| detect +2 % | paired t, two-sided α = 0.05 | **{pairs_to_detect(sd, e2)}** | "
        f"{pairs_to_detect(sd_high, e2)} |"
    )
    print(
        f"| detect +3 % | paired t, two-sided α = 0.05 | {pairs_to_detect(sd, m3)} | "
        f"{pairs_to_detect(sd_high, m3)} |"
    )
    print("\n## The plan's two looks (40 and 80 pairs, each at 0.0294)\n")
    for look in LOOKS:
        half = 100 * stats.t.ppf(1 - ALPHA / 2, look - 1) * sd / np.sqrt(look) / ref
        print(
            f"- At {look} pairs alone: equivalence within ±3 % found with power "
            f"{tost_power(sd, m3, look, ALPHA):.2f} if the true difference is 0; +2 % "
            f"detected with power {detect_power(sd, e2, look, ALPHA):.2f}; the 97.06 % "
            f"interval's half-width ±{half:.2f} %."
        )
    print(
        f"\nThe whole design, {SIMULATED:,} simulated studies a row (SD {sd:.2f}, numpy seed 48):\n"
    )
    print("| true difference | finds an effect | finds equivalence (±3 %) | inconclusive "
          "| decided at the first look |")  # fmt: skip
    print("|---|---:|---:|---:|---:|")
    rng = np.random.default_rng(48)
    for pct in (0.0, 1.0, 2.0, 3.0):
        o = simulate(sd, m3, pct / 100 * ref, rng)
        print(
            f"| {pct:+.0f} % | {o['effect']:.3f} | {o['equivalent']:.3f} | "
            f"{o['inconclusive']:.3f} | {o['at first look']:.3f} |"
        )
    print(
        "\n(At a true difference of 0 the first column is the design's false-positive rate, "
        "which Pocock's level holds at or under 0.05.)\n"
    )
    print("## Compute on each CPU kind\n")
    print(
        "From the wall time of every finished `authors` run of replication 2 that ran alone "
        f"and was never resumed ({', '.join(ALONE)}); one run a core, 1 torch thread. A "
        "2-core machine runs two at a time.\n"
    )
    print(
        "| CPU kind | runs measured | a run: fastest, median, slowest (min) | "
        + " | ".join(f"{k}: {v} runs" for k, v in STAGE_RUNS.items())
        + " | all 200 runs |"
    )
    print("|---|---:|---|" + "---|" * (len(STAGE_RUNS) + 1))
    for kind in KINDS:
        t = np.array(minutes.get(kind, []))
        if not len(t):
            continue
        fast, median = t.min(), float(np.median(t))
        usable = kind != "EPYC AVX2"

        def hours(runs: int, fast: float = fast, median: float = median) -> str:
            return f"{runs * fast / 60:.1f}-{runs * median / 60:.1f} run-h"

        cells = [hours(v) if usable else "none (no bfloat16)" for v in STAGE_RUNS.values()]
        print(
            f"| {KINDS[kind]} | {len(t)} | {fast:.1f}, {median:.1f}, {t.max():.1f} | "
            + " | ".join(cells)
            + f" | {hours(sum(STAGE_RUNS.values())) if usable else 'none'} |"
        )
    print(
        "\nRun-hours at the fastest run and at the median run; on a 2-core machine the wall "
        "time is half. The AVX2-only EPYC's runs are float32 (`A-auto-fp32`), shown for "
        "scale: the study is bfloat16 and does not run there."
    )
    bf16 = [np.median(t) for k, t in minutes.items() if k != "EPYC AVX2"]
    stage1 = (STAGE_RUNS["stage 1 (agent, procedure)"] + STAGE_RUNS["its auto arm"]) / 60
    print(
        f"\nAgainst issue 48's {BUDGET_HOURS} hours of bfloat16 compute: stage 1 with its auto "
        f"arm takes {stage1 * min(bf16):.1f}-{stage1 * max(bf16):.1f} run-hours at the median "
        f"run, the whole study {200 / 60 * min(bf16):.1f}-{200 / 60 * max(bf16):.1f}: "
        + (
            "it does not fit, so the plan is committed, not run."
            if stage1 * min(bf16) > BUDGET_HOURS
            else "stage 1 fits."
        )
    )


if __name__ == "__main__":
    main()
