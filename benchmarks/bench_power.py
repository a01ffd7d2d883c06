"""What a power analysis costs: one comparison of 10 + 10 agents' R_T, for an effect that a
few agents detect, one that needs dozens, and none at all (the search runs to `max_n`).

The report runs one per method besides the baseline, so this is what the Power section adds
to a report. Run: `python -m benchmarks.bench_power`.
"""

from __future__ import annotations

import time

import numpy as np

from analysis.power import DEFAULT_DRAWS, DEFAULT_MAX_N, power_analysis

EFFECTS = {"large (d = 2)": 2.0, "medium (d = 0.5)": 0.5, "none (d = 0)": 0.0}


def seconds(d: float) -> tuple[float, int | None]:
    """Seconds for one comparison whose observed d is exactly `d`, and the n it finds."""
    rng = np.random.default_rng(0)
    base, noise = rng.normal(0.0, 1.0, 10), rng.normal(0.0, 1.0, 10)
    scale = base.std(ddof=1)
    arm = (noise - noise.mean()) / noise.std(ddof=1) * scale + base.mean() + d * scale
    started = time.perf_counter()
    result = power_analysis({"autonomous": base, "human": arm}, "autonomous")
    return time.perf_counter() - started, result.comparisons[0].sample_sizes[0].bootstrap


def main() -> None:
    print(f"{DEFAULT_DRAWS} simulated studies per size, sizes searched up to {DEFAULT_MAX_N}")
    for name, d in EFFECTS.items():
        took, needed = seconds(d)
        print(f"one comparison, effect {name:17}: {took:.2f} s (80 % needs {needed} per arm)")


if __name__ == "__main__":
    main()
