"""R_T with the compiled convolutions against the PyTorch update, seed by seed: is the
difference inside ±3 %? (issue 45, point 3: "R_T of 10 paired seeds equivalent within
±3 % (two one-sided tests)").

    python -m benchmarks.conv_kernel_equivalence --scale reduced --pairs 10
    python -m benchmarks.conv_kernel_equivalence --scale smoke --pairs 2     # seconds

For each of `--pairs` seeds it runs the autonomous learner twice in this process, one
torch thread, the same seed and settings: with `conv_kernel none` (the reference) and
with the compiled kernels for all three layers in the run's precision (`avx2:1-3` for
float32, `avx512bf16:1-3` for bfloat16). R_T is the sum of the training episodes'
collected rewards (`analysis`'s R_T). It prints each pair's R_T, their difference and the
first step at which the two took another action, then the mean difference (kernels
minus PyTorch) with its 90 % interval and the two one-sided paired t-tests against
-3 % and +3 % of the reference arm's mean R_T (`analysis.equivalence.paired_tost`, α =
0.05): equivalence is shown when both reject. Fewer than 10 pairs give an estimate, not
a demonstration.

`--scale` names the run's size (`SCALES`): `smoke` (the records fixture's: seconds a
pair), `reduced` (60 training episodes of the paper's run, the rest the paper's: about
a fifth of a paper-scale run), `paper` (the paper's 300 episodes). The sorting task in
fast motion, the `--preset` (paper by default) and `--precision` (the one this CPU runs
natively by default).

Not a `bench_` module: `python -m benchmarks` runs those one after the other, and this
one's default, 10 pairs at the reduced scale, is hours of CPU (a paper-scale run is 13
min on the AVX2-only EPYC, one thread).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from analysis.equivalence import paired_tost, relative_margin
from learner import machine

SCALES: dict[str, dict[str, Any]] = {
    "smoke": {
        "pretraining_steps": 60,
        "episodes": 3,
        "max_episode_steps": 30,
        "batch_size": 16,
        "memory_size": 500,
        "epsilon_decay": 0.99,
    },
    "reduced": {"episodes": 60},
    "paper": {},
}
"""The run's size: the fields changed from the preset's (the paper's 300 episodes of up to
250 steps, 1,000 pretraining steps, batches of 128)."""
MARGIN = 0.03
"""The equivalence margin, a fraction of the reference arm's mean R_T (the plan's 3 %)."""
ALPHA = 0.05
"""Each one-sided test's level: the interval is the 90 % one."""


@dataclass(frozen=True)
class Arm:
    """One run: its R_T, its actions step by step, and the seconds it took."""

    r_t: float
    actions: list[int]
    seconds: float


def run(seed: int, conv_kernel: str, precision: str, scale: str, preset: str) -> Arm:
    """The autonomous learner's run on `seed` with `conv_kernel`."""
    from learner.run import RunSpec

    config = {
        **SCALES[scale],
        "update": "fast",
        "precision": precision,
        "conv_kernel": conv_kernel,
        "device": "cpu",
        "torch_threads": 1,
    }
    spec = RunSpec.from_json(
        {
            "method": "autonomous",
            "seed": seed,
            "motion": "fast",
            "preset": preset,
            "config": config,
        }
    ).validate()
    steps: list[int] = []
    rewards: list[float] = []

    class Keep:
        def on_step(self, record: Any) -> None:
            steps.append(record.action)

        def on_episode(self, record: Any) -> None:
            if record.stage == "train":
                rewards.append(record.collected_reward)

    env = spec.make_env()
    started = time.perf_counter()
    try:
        spec.make_trainer(env, spec.make_advisor(), [Keep()]).run()
    finally:
        env.close()
    return Arm(float(sum(rewards)), steps, time.perf_counter() - started)


def first_other_action(a: Arm, b: Arm) -> int | None:
    """The first step (from 1) at which the two runs took another action, or None."""
    for step, (x, y) in enumerate(zip(a.actions, b.actions, strict=False), start=1):
        if x != y:
            return step
    return None if len(a.actions) == len(b.actions) else min(len(a.actions), len(b.actions)) + 1


def one_sided_p(differences: np.ndarray, margin: float) -> tuple[float, float]:
    """The paired t-tests' p-values of H0 "mean difference <= -margin" and of H0 "mean
    difference >= +margin" (both 0 or 1 where the pairs' differences do not vary)."""
    mean = float(differences.mean())
    se = float(differences.std(ddof=1) / np.sqrt(differences.size))
    if se == 0:
        return (0.0 if mean > -margin else 1.0), (0.0 if mean < margin else 1.0)
    dof = differences.size - 1
    return float(stats.t.sf((mean + margin) / se, dof)), float(
        stats.t.cdf((mean - margin) / se, dof)
    )


def kernel_for(precision: str) -> str:
    """The compiled variant for `precision`, for all three layers, where it runs here."""
    for variant, (_, variant_precision) in machine.CONV_KERNEL_VARIANTS.items():
        if variant_precision == precision and machine.conv_kernel_runs(variant):
            return machine.conv_kernel_name(variant, machine.CONV_KERNEL_LAYERS)
    sys.exit(
        f"no compiled variant computes {precision} convolutions here ({machine.cpu_kind()}): "
        "run `make kernels`, or choose the other --precision"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scale", choices=sorted(SCALES), default="reduced")
    parser.add_argument("--pairs", type=int, default=10, help="seeds, each run twice")
    parser.add_argument("--seed", type=int, default=0, help="the first seed")
    parser.add_argument("--preset", default="paper")
    parser.add_argument(
        "--precision",
        choices=("bf16", "fp32"),
        default="bf16" if machine.bf16_native_cpu() else "fp32",
    )
    args = parser.parse_args(argv)
    if args.pairs < 2:
        parser.error("--pairs: a paired test needs at least 2 pairs")
    kernel = kernel_for(args.precision)
    load = os.getloadavg()[0]
    print(
        f"{machine.cpu_kind()}, load {load:.2f}; scale {args.scale}, preset {args.preset}, "
        f"{args.precision}, one thread; conv_kernel none against {kernel}; "
        f"seeds {args.seed}-{args.seed + args.pairs - 1}"
    )
    print("seed  R_T none  R_T kernels  difference  first other action  seconds none/kernels")
    reference, kernels = [], []
    for seed in range(args.seed, args.seed + args.pairs):
        off = run(seed, "none", args.precision, args.scale, args.preset)
        on = run(seed, kernel, args.precision, args.scale, args.preset)
        reference.append(off.r_t)
        kernels.append(on.r_t)
        other = first_other_action(off, on)
        print(
            f"{seed:4d}  {off.r_t:8.2f}  {on.r_t:11.2f}  {on.r_t - off.r_t:+10.2f}  "
            f"{'none' if other is None else f'step {other}':>18}  "
            f"{off.seconds:.1f}/{on.seconds:.1f}",
            flush=True,
        )
    margin = relative_margin(reference, MARGIN)
    result = paired_tost(reference, kernels, margin, alpha=ALPHA)
    low, high = result.interval
    below, above = one_sided_p(np.asarray(kernels) - np.asarray(reference), margin)
    mean_reference = float(np.mean(reference))
    print(
        f"mean difference (kernels - none) {result.mean_difference:+.3f} "
        f"({100 * result.mean_difference / abs(mean_reference):+.2f} % of the reference's "
        f"mean R_T {mean_reference:.2f}); 90 % interval [{low:+.3f}, {high:+.3f}]"
    )
    print(
        f"two one-sided tests at ±{100 * MARGIN:.0f} % (±{margin:.3f}): "
        f"H0 difference <= -{margin:.3f}: p = {below:.3g}; "
        f"H0 difference >= +{margin:.3f}: p = {above:.3g}"
    )
    estimate = "" if args.pairs >= 10 else " (fewer than 10 pairs: an estimate)"
    print(f"{result.sentence()}{estimate}; load now {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
