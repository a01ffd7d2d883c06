"""What `copy.deepcopy(env)` costs: a new PyBullet world, then the episode replayed.

Median of several copies, after 0, 20 and 100 steps of an episode, in both motion modes
(the replay is what grows with the episode; the physics mode simulates every step again).
Run: `python -m benchmarks.bench_copy`.
"""

from __future__ import annotations

import copy
import statistics
import time

import numpy as np

import sim

REPEATS = 5


def copy_seconds(motion: str, steps: int) -> float:
    env = sim.SortingEnv(motion=motion)
    env.reset(seed=1)
    rng = np.random.default_rng(0)
    done = 0
    while done < steps:
        _, _, terminated, truncated, _ = env.step(int(rng.integers(1, 3)))  # moves only
        done += 1
        assert not (terminated or truncated)
    times = []
    for _ in range(REPEATS):
        started = time.perf_counter()
        clone = copy.deepcopy(env)
        times.append(time.perf_counter() - started)
        clone.close()
    env.close()
    return statistics.median(times)


def main() -> None:
    for motion in ("fast", "physics"):
        for steps in (0, 20, 100):
            seconds = copy_seconds(motion, steps)
            print(f"deepcopy, {motion:7} mode, {steps:3} steps in: {seconds:.3f} s")


if __name__ == "__main__":
    main()
