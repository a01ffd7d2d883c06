"""How fast a population of agents learns: the update alone, and a whole step in parts.

    python -m benchmarks.bench_population                      # sizes 1 2 4 8 16, 1 thread
    python -m benchmarks.bench_population --sizes 1 4 --threads 2 --repeats 3

1. The matrix-multiply rate of this machine: 2048x2048 `torch.matmul` in bfloat16 and
   float32 (GFLOPS, median of several): what the vector units can do.
2. The update alone, batch 128, for populations of N agents: the stacked update of N
   agents (`learner.stacked`, with per-agent and grouped convolutions) against N
   single-agent updates (`DQNAgent.update` one after the other), in alternating blocks
   so that both see the same machine load; the ratio is taken per block pair and its
   median reported. Agent-updates per second, and the achieved rate in GFLOPS of the
   network's own FLOPs (torch's FLOP counter on the plain float32 update: the function,
   not the zeros the space-to-depth kernels add) as a fraction of the matmul rates.
   Where the CPU has two cores per torch thread, also: 2 workers (each agent's update
   on one of two threads, `Population(workers=2)`) against N single updates with twice
   the torch threads: whole updates in parallel against each operation in parallel.
3. A population step split into its parts: the update, action selection (one batched
   forward pass), simulation (the environments' steps less their rendering), rendering
   (the 64x64 camera image), and the rest (replay memory, records, bookkeeping).
4. The space-to-depth kernels cached between optimizer steps (`PhaseConvForward`) against
   rebuilt on every forward pass (as before the cache), alternating block by block in one
   process: the update alone, action selection alone, and a whole population step in
   training, with the plain float32 reference update (`bench_learner.ReferenceDQN`) timed
   in the same rounds; ratios per round, medians reported. Beside it, action selection
   with the configs' check (`learner.config.shared_config`) cached against rebuilt.

Other processes share the CPUs: compare ratios, not times. The CPU kind and the load
average are printed with the numbers. Populations end to end, through `ideeprl batch` with
records in SQLite and checkpoints: `benchmarks/bench_population_batch.py`.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import torch

from benchmarks.bench_learner import BATCH, ReferenceDQN, real_frames
from learner.device import bf16_native


def cpu_kind() -> str:
    """The CPU's model name and whether it multiplies bfloat16 natively."""
    name = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    name = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    bf16 = getattr(torch.cpu, "_is_avx512_bf16_supported", lambda: False)()
    return f"{name}, {os.cpu_count()} CPUs" + (", AVX-512 BF16" if bf16 else "")


def load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def matmul_gflops(dtype: torch.dtype, repeats: int, size: int = 2048) -> float:
    a = torch.randn(size, size, dtype=dtype)
    b = torch.randn(size, size, dtype=dtype)
    for _ in range(2):
        torch.matmul(a, b)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        torch.matmul(a, b)
        times.append(time.perf_counter() - start)
    return 2 * size**3 / statistics.median(times) / 1e9


def update_flops() -> float:
    """FLOPs of one plain float32 update of batch 128 (torch's FLOP counter)."""
    from torch.utils.flop_counter import FlopCounterMode

    from learner.agent import DQNAgent
    from learner.config import DQNConfig
    from learner.replay import ReplayMemory

    agent = DQNAgent(DQNConfig(update="plain"), torch.device("cpu"))
    memory = _memory(agent, real_frames(BATCH + 2))
    batch = memory.sample(BATCH, np.random.default_rng(0))
    counter = FlopCounterMode(display=False)
    with counter:
        agent.update(batch)
    assert isinstance(memory, ReplayMemory)
    return float(counter.get_total_flops())


def _memory(agent: Any, frames: list[np.ndarray]) -> Any:
    from learner.replay import ReplayMemory

    rng = np.random.default_rng(0)
    memory = ReplayMemory(len(frames), agent.frame_shape)
    packed = [agent.encode(frame) for frame in frames]
    for t in range(len(frames) - 1):
        reward = float(rng.choice([0.0, 0.4, -0.01, -1.0]))
        memory.add(packed[t], t % 4, reward, packed[t + 1], t % 40 == 39, False)
    return memory


def _time_block(work: Callable[[], Any], block: int) -> float:
    start = time.perf_counter()
    for _ in range(block):
        work()
    return (time.perf_counter() - start) / block


def bench_update(size: int, repeats: int, block: int, frames: list[np.ndarray]) -> dict:
    """Seconds per population update (N agent-updates) in each layout, against N single
    updates (`DQNAgent.update` one after the other), through `Population._update`."""
    import sim
    from learner.config import DQNConfig
    from learner.population import Member, Population

    threads = torch.get_num_threads()
    config = DQNConfig(torch_threads=threads, memory_size=len(frames))
    members = [Member(sim.SortingEnv(motion="fast"), seed) for seed in range(size)]
    population = Population(config, members, layout="stacked-actions")
    rng = np.random.default_rng(0)
    for trainer in population.trainers:
        packed = [trainer.agent.encode(frame) for frame in frames]
        for t in range(len(frames) - 1):
            reward = float(rng.choice([0.0, 0.4, -0.01, -1.0]))
            trainer.memory.add(packed[t], t % 4, reward, packed[t + 1], t % 40 == 39, False)
    trainers = population.trainers
    agents = [t.agent for t in trainers]

    def single() -> list[float]:
        batches = [t.memory.sample(BATCH, t._memory_rng) for t in trainers]
        return [a.update(b) for a, b in zip(agents, batches, strict=True)]

    def variant(layout: str, conv: str = "loop", workers: int = 1) -> Callable[[], Any]:
        def work() -> list[float]:
            population.layout, population.conv = layout, conv  # type: ignore[assignment]
            population.workers, population._pool = workers, pools.get(workers)
            return population._update(trainers)

        return work

    pools = {w: ThreadPoolExecutor(w) for w in (2,) if (os.cpu_count() or 1) >= 2 * threads}
    works: dict[str, Callable[[], Any]] = {"single": single, "stacked": variant("stacked")}
    if size > 1:
        works["stacked grouped"] = variant("stacked", "grouped")
    if pools:
        works["2 workers"] = variant("stacked-actions", workers=2)
        works["single, 2x threads"] = lambda: _with_threads(2 * threads, single)
    for work in works.values():
        work()  # warm-up: allocator, oneDNN kernels
    times: dict[str, list[float]] = {name: [] for name in works}
    for _ in range(repeats):
        for name, work in works.items():
            times[name].append(_time_block(work, block))
    for pool in pools.values():
        pool.shutdown()
    for member in members:
        member.env.close()
    ratios = {
        name: statistics.median(s / t for s, t in zip(times["single"], times[name], strict=True))
        for name in works
        if name != "single"
    }
    return {"seconds": {k: statistics.median(v) for k, v in times.items()}, "ratios": ratios}


def _with_threads(threads: int, work: Callable[[], Any]) -> Any:
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return work()
    finally:
        torch.set_num_threads(before)


class _Timed:
    """Accumulates the wall time of calls to a wrapped function under a name."""

    def __init__(self, totals: dict[str, float], name: str, function: Callable) -> None:
        self.totals, self.name, self.function = totals, name, function

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return self.function(*args, **kwargs)
        finally:
            self.totals[self.name] += time.perf_counter() - start


def profile_step(size: int, steps: int, workers: int = 1) -> dict[str, float]:
    """Milliseconds per population step (of `size` agents in training) by part, in the
    layout `auto` picks here."""
    import sim
    from learner.config import DQNConfig
    from learner.population import Member, Population

    config = DQNConfig(
        torch_threads=torch.get_num_threads(), memory_size=2000, pretraining_steps=BATCH
    )
    members = [Member(sim.SortingEnv(motion="fast"), seed) for seed in range(size)]
    population = Population(config, members, workers=workers)
    while any(t.stage == "pretrain" for t in population.trainers):
        population.step()
    population.step()  # warm-up
    totals = dict.fromkeys(("update", "action selection", "simulation", "rendering"), 0.0)
    population._update = _Timed(totals, "update", population._update)  # type: ignore[method-assign]
    population._q_values = _Timed(totals, "action selection", population._q_values)  # type: ignore[method-assign]
    for trainer in population.trainers:
        env = trainer.env.unwrapped
        env.step = _Timed(totals, "simulation", env.step)  # type: ignore[method-assign]
        env._camera.image = _Timed(totals, "rendering", env._camera.image)  # type: ignore[attr-defined]
    start = time.perf_counter()
    for _ in range(steps):
        population.step()
    total = time.perf_counter() - start
    totals["simulation"] -= totals["rendering"]  # env.step renders; resets render too
    totals["rest"] = total - (
        totals["update"] + totals["action selection"] + totals["simulation"] + totals["rendering"]
    )
    population.close()
    for member in members:
        member.env.close()
    return {name: 1000 * seconds / steps for name, seconds in totals.items()} | {
        "total": 1000 * total / steps
    }


def _rebuilt_weights(fast: Any) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """`PhaseConvForward.weights` as before the cache: the kernels rebuilt from the weights
    on every call, differentiable through autograd's own graph of their construction."""
    convs = fast.network.convs
    return [(fast._build(conv.weight, i), conv.bias) for i, conv in enumerate(convs)]


def _training_population(size: int) -> Any:
    """A population of `size` paper-preset agents (64x64, batch 128) past pretraining."""
    import sim
    from learner.config import DQNConfig
    from learner.population import Member, Population

    config = DQNConfig(
        torch_threads=torch.get_num_threads(), memory_size=2000, pretraining_steps=BATCH
    )
    members = [Member(sim.SortingEnv(motion="fast"), seed) for seed in range(size)]
    population = Population(config, members)
    while any(t.stage == "pretrain" for t in population.trainers):
        population.step()
    return population


def bench_kernel_cache(size: int, repeats: int, block: int, frames: list[np.ndarray]) -> dict:
    """Seconds of the update alone, action selection alone and a population step of `size`
    agents, kernels cached ("cached") against rebuilt on every pass ("rebuilt"), and of
    the float32 reference update, in alternating blocks; ratios rebuilt/cached and
    reference/update per round."""
    from learner.phase_conv import PhaseConvForward

    population = _training_population(size)
    trainers = population.trainers
    images = frames[:size]
    reference = ReferenceDQN()
    for t in range(len(frames) - 1):
        reference.remember(frames[t], t % 4, 0.0, frames[t + 1], t % 40 == 39)
    parts: dict[str, Callable[[], Any]] = {
        "update": lambda: population._update(trainers),
        "action selection": lambda: population._q_values(trainers, images),
        "population step": population.step,
    }
    cached = PhaseConvForward.weights
    variants = {"rebuilt": _rebuilt_weights, "cached": cached}
    times: dict[str, list[float]] = {"reference": []}
    try:
        for part, work in parts.items():
            for name, weights in variants.items():
                PhaseConvForward.weights = weights  # type: ignore[method-assign]
                work()  # warm-up
                times[f"{part}, {name}"] = []
        for round_ in range(repeats):
            times["reference"].append(_time_block(reference.update, block))
            for part, work in parts.items():
                order = list(variants.items())  # each first in every other round
                for name, weights in order[:: 1 if round_ % 2 else -1]:
                    PhaseConvForward.weights = weights  # type: ignore[method-assign]
                    times[f"{part}, {name}"].append(_time_block(work, block))
    finally:
        PhaseConvForward.weights = cached  # type: ignore[method-assign]
        population.close()
        for trainer in trainers:
            trainer.env.close()

    def ratio(numerator: str, denominator: str) -> float:
        pairs = zip(times[numerator], times[denominator], strict=True)
        return statistics.median(a / b for a, b in pairs)

    ratios = {
        f"{part}: rebuilt / cached": ratio(f"{part}, rebuilt", f"{part}, cached") for part in parts
    }
    for name in variants:
        per_agent = size * ratio("reference", f"update, {name}")
        ratios[f"reference / agent-update, {name}"] = per_agent
    return {"seconds": {k: statistics.median(v) for k, v in times.items()}, "ratios": ratios}


def bench_config_check(size: int, repeats: int, frames: list[np.ndarray]) -> dict:
    """Milliseconds of action selection for `size` agents with `shared_config` cached
    ("after") against rebuilt on every call ("before"), in alternating blocks of 20 calls;
    the median ratio before/after per round pair."""
    import learner.stacked
    import sim
    from learner.config import DQNConfig
    from learner.population import Member, Population

    cached = learner.stacked.shared_config
    config = DQNConfig(torch_threads=torch.get_num_threads())
    population = Population(config, [Member(sim.SortingEnv(motion="fast"), s) for s in range(size)])
    trainers, images = population.trainers, frames[:size]
    variants = {"before": cached.__wrapped__, "after": cached}
    times: dict[str, list[float]] = {name: [] for name in variants}
    try:
        for round_ in range(2 * repeats):
            for name, check in list(variants.items())[:: 1 if round_ % 2 else -1]:
                learner.stacked.shared_config = check  # type: ignore[attr-defined]
                population._q_values(trainers, images)
                times[name].append(_time_block(lambda: population._q_values(trainers, images), 20))
    finally:
        learner.stacked.shared_config = cached  # type: ignore[attr-defined]
        for trainer in trainers:
            trainer.env.close()
    ratio = statistics.median(a / b for a, b in zip(times["before"], times["after"], strict=True))
    return {"ms": {k: 1000 * statistics.median(v) for k, v in times.items()}, "ratio": ratio}


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_population")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=5, help="block rounds for the update")
    parser.add_argument("--block", type=int, default=2, help="updates per timed block")
    parser.add_argument("--profile-sizes", type=int, nargs="+", default=[1, 8])
    parser.add_argument("--profile-steps", type=int, default=20)
    parser.add_argument("--cache-sizes", type=int, nargs="*", default=[1, 4, 8])
    parser.add_argument("--only-cache", action="store_true", help="only part 4")
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore", message="Using padding='same' with even kernel")
    torch.set_num_threads(args.threads)
    print(f"{cpu_kind()}; torch {torch.__version__}, {args.threads} thread(s); {load()}")

    if args.cache_sizes:
        print(
            f"\nkernels cached against rebuilt on every pass, paper preset, batch {BATCH} "
            f"(median of {args.repeats} rounds of {args.block}-call blocks; the reference "
            "update times the agent-update of N=1)"
        )
        for size in args.cache_sizes:
            r = bench_kernel_cache(size, args.repeats, args.block, real_frames(300))
            seconds = ", ".join(f"{k} {1000 * v:.2f}" for k, v in r["seconds"].items())
            ratios = ", ".join(f"{k} {v:.3f}x" for k, v in r["ratios"].items())
            print(f"  N={size}: ms: {seconds}\n        ratios: {ratios}; {load()}", flush=True)
        for size in args.cache_sizes:
            r = bench_config_check(size, args.repeats, real_frames(size))
            print(
                f"  action selection N={size}, shared_config rebuilt {r['ms']['before']:.2f} ms, "
                f"cached {r['ms']['after']:.2f} ms: {r['ratio']:.2f}x; {load()}",
                flush=True,
            )
    if args.only_cache:
        return

    cores = [args.threads] + (
        [2 * args.threads] if (os.cpu_count() or 1) >= 2 * args.threads else []
    )
    # bfloat16 only where the CPU multiplies it natively: emulated, one 2048x2048 product
    # takes minutes (the AVX2-only EPYC), and the learner computes in float32 there
    native = bf16_native(torch.device("cpu"))
    peaks: dict[int, tuple[float, float]] = {}
    for n in cores:
        peaks[n] = _with_threads(
            n,
            lambda: (
                matmul_gflops(torch.bfloat16, 7) if native else float("nan"),
                matmul_gflops(torch.float32, 7),
            ),
        )
        bf16_text = f"{peaks[n][0]:.0f} GFLOPS" if native else "not native (not measured)"
        print(
            f"\n2048x2048 matmul on {n} thread(s): bfloat16 {bf16_text}, "
            f"float32 {peaks[n][1]:.0f} GFLOPS; {load()}"
        )
    flops = update_flops()
    print(f"one update of batch {BATCH}: {flops / 1e9:.2f} GFLOP (torch's FLOP counter)")

    frames = real_frames(600)
    print(
        f"\nthe update alone, batch {BATCH} (median of {args.repeats} rounds of "
        f"{args.block}-update blocks; x: N single updates' time / the variant's, per round)"
    )
    for size in args.sizes:
        r = bench_update(size, args.repeats, args.block, frames)
        print(f"  N={size}: {load()}")
        for name, seconds in r["seconds"].items():
            n = 2 * args.threads if name in ("2 workers", "single, 2x threads") else args.threads
            bf16, fp32 = peaks[n]
            rate = size * flops / seconds / 1e9
            ratio = f"{r['ratios'][name]:.2f}x" if name in r["ratios"] else "1 (reference)"
            print(
                f"    {name:19} {1000 * seconds:6.0f} ms  {ratio:>13}  "
                f"{size / seconds:5.1f} agent-updates/s  {rate:4.0f} GFLOPS = "
                + (f"{100 * rate / bf16:4.1f} % of bf16 matmul, " if native else "")
                + f"{100 * rate / fp32:3.0f} % of fp32 "
                f"({n} core(s))",
                flush=True,
            )

    print(f"\na population step in training, by part (ms per step, {args.profile_steps} steps)")
    for size in args.profile_sizes:
        for workers in (1, 2) if size > 1 else (1,):
            parts = profile_step(size, args.profile_steps, workers)
            line = ", ".join(f"{k} {v:.1f}" for k, v in parts.items())
            print(
                f"  N={size:2}, {workers} worker(s): {line}; {parts['total'] / size:.1f} ms per "
                f"agent-step; {load()}",
                flush=True,
            )


if __name__ == "__main__":
    main()
