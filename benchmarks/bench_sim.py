"""Milliseconds per action of the sorting scenario, render included, in both motion modes.

Targets on the project's 2-core machine: physics <= 15 ms, fast <= 5 ms (median per
action). Each case runs `--actions` actions in `--rounds` rounds and reports the quietest
round's median, since other work on a shared machine only ever slows a round down. As a
reference measured in the same run, the 64x64 camera image alone is timed too, so the
ratio column says how many renders an action costs whatever the machine's load. Resets
are timed apart: they happen once an episode, not once an action.

    python -m benchmarks.bench_sim [--actions 300] [--rounds 5]
"""

import argparse
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

import sim

TARGET_MS = {"physics": 15.0, "fast": 5.0}


@dataclass
class Timing:
    """Per-call milliseconds of one case over its rounds."""

    wall: list[float]
    """Median wall-clock milliseconds of each round."""
    cpu: list[float]
    """Median process CPU milliseconds of each round (less sensitive to other processes)."""

    @property
    def quietest(self) -> tuple[float, float]:
        return min(self.wall), min(self.cpu)


def time_calls(call: Callable[[], object], count: int) -> tuple[float, float]:
    """Median wall and CPU milliseconds of `count` calls."""
    wall, cpu = [], []
    for _ in range(count):
        w, c = time.perf_counter(), time.process_time()
        call()
        cpu.append(1000 * (time.process_time() - c))
        wall.append(1000 * (time.perf_counter() - w))
    return statistics.median(wall), statistics.median(cpu)


def time_actions(env: sim.SortingEnv, policy: str, count: int, seed: int) -> tuple[float, float]:
    """Median ms per `step` over `count` actions; episodes restart untimed when they end."""
    rng = np.random.default_rng(seed)
    _, info = env.reset(seed=seed)
    wall, cpu = [], []
    for _ in range(count):
        action = sim.oracle_action(info, "color") if policy == "oracle" else int(rng.integers(4))
        w, c = time.perf_counter(), time.process_time()
        _, _, terminated, truncated, info = env.step(action)
        cpu.append(1000 * (time.process_time() - c))
        wall.append(1000 * (time.perf_counter() - w))
        if terminated or truncated:
            _, info = env.reset(seed=int(rng.integers(1 << 30)))
    return statistics.median(wall), statistics.median(cpu)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--actions", type=int, default=300, help="actions per round (>= 200)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds per case")
    args = parser.parse_args(argv)

    envs = {motion: sim.SortingEnv(motion=motion) for motion in ("fast", "physics")}
    cases: dict[str, Callable[[int], tuple[float, float]]] = {
        "render only (64x64 camera image)": lambda r: time_calls(
            envs["fast"]._camera.image, args.actions
        ),
    }
    for motion, env in envs.items():
        for policy in ("random", "oracle"):
            cases[f"{motion}, {policy} actions"] = lambda r, env=env, policy=policy: time_actions(
                env, policy, args.actions, r
            )
        cases[f"{motion}, reset"] = lambda r, env=env: time_calls(
            lambda: env.reset(seed=r), max(10, args.actions // 20)
        )
    timings = {name: Timing([], []) for name in cases}
    for r in tqdm(range(args.rounds), desc="rounds", unit="round"):
        for name, case in cases.items():
            wall, cpu = case(r)
            timings[name].wall.append(wall)
            timings[name].cpu.append(cpu)
    for env in envs.values():
        env.close()

    render_wall, render_cpu = timings["render only (64x64 camera image)"].quietest
    print(f"\nmedian ms per call, quietest of {args.rounds} rounds of {args.actions} actions")
    print(f"{'case':36} {'wall ms':>8} {'cpu ms':>8} {'renders':>8}  target")
    for name, timing in timings.items():
        wall, cpu = timing.quietest
        motion = name.split(",")[0]
        target = ""
        if "actions" in name:
            verdict = "ok" if wall <= TARGET_MS[motion] else "OVER"
            target = f"<= {TARGET_MS[motion]:g} ms {verdict}"
        print(f"{name:36} {wall:8.2f} {cpu:8.2f} {wall / render_wall:8.1f}  {target}")
    print(f"(render reference: {render_wall:.2f} ms wall, {render_cpu:.2f} ms cpu)")


if __name__ == "__main__":
    main()
