"""How fast the learner's update is, what a paper-scale run costs, and its memory.

    python -m benchmarks.bench_learner                  # update speed, run time, memory
    python -m benchmarks.bench_learner --curves 60      # + fast vs plain learning curves
    python -m benchmarks.bench_learner --profile        # the update by part, and its bound

1. The update: the learner's (`DQNConfig(update="fast")`) against a reference written the
   way the common DQN references write it (a replay deque of numpy frames, float32
   tensors built from numpy each step, default NCHW layout, `padding="same"` convs and
   `MaxPool2d`, no tricks), same network, batch 128, RMSprop. Blocks of updates of each
   alternate, so both see the same machine load; the ratio is taken per block pair and
   its median reported. Other processes share the CPUs: compare ratios, not times.
   A second reference is the library's best plain path, what a careful user writes:
   the learner's own `QNetwork` in channels-last under `torch.autocast` (bfloat16 where
   the CPU has it natively, as the fast update), uint8 frames kept in one tensor on the
   device and converted there after an `index_select` (`CarefulDQN`). Where the compiled
   convolutions run here (`make kernels`, `learner.conv_kernel`), the learner with them for
   all three layers is timed in the same blocks, against the learner's PyTorch update and
   the plain reference, with the network's own FLOPs a second against the core's
   matrix-multiply rate measured in the same run.
2. A paper-scale run (300 episodes) on the fast simulator, extrapolated from measured
   pretraining and >= 2,000 training steps to 6,700 training steps: what 300 episodes
   took the autonomous agents of docs/results/ (6,637 to 6,731; their epsilon is still
   3.5 % at the end; the authors' logs show 0.08-0.13 at episode 150 and 1 % only after
   episode 325, whatever the paper's text says).
3. Resident memory with a full 20,000-transition replay memory (in a fresh process), in
   stages: torch alone is about 280 MiB, the memory adds its frames (235 MiB) and no more.
4. With --profile: the update alone, one thread, by part (torch's profiler over blocks of
   updates, several rounds, medians): each convolution's forward and backward with its
   rate in GFLOPS, the layout copies, the element-wise work (the phase max-pool, ReLU and
   their gradients), the dense layers and the rest; then what the convolutions alone cost
   the paper's experiment (140,739 updates on 2 cores): the bound the rest cannot beat.
5. With --curves N: collected reward of N training episodes, the fast update against the
   trainer's plain float32 update (`update="plain"`: NCHW convs and max-pools, like the
   reference), same seeds and everything else, drawn to
   docs/images/learner_fast_vs_plain.png (takes a while: the plain update is the slow one).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time
import warnings
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

BATCH = 128
PAPER_TRAINING_STEPS = 6_700
"""Training steps of a 300-episode autonomous run on this platform (docs/results/)."""
CURVES_PNG = Path("docs/images/learner_fast_vs_plain.png")


class ReferenceDQN:
    """The DQN update in the plain style of the common references."""

    def __init__(self, capacity: int = 20_000, seed: int = 0) -> None:
        torch.manual_seed(seed)
        self.net = nn.Sequential(
            nn.Conv2d(3, 4, 8, padding="same"), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(4, 8, 4, padding="same"), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(8, 16, 2, padding="same"), nn.ReLU(), nn.MaxPool2d(2),
            nn.Flatten(), nn.Linear(1024, 256), nn.ReLU(), nn.Linear(256, 4),
        )  # fmt: skip
        self.optimizer = torch.optim.RMSprop(self.net.parameters(), lr=1e-3, alpha=0.9, eps=1e-7)
        self.memory: deque = deque(maxlen=capacity)
        self.gamma = 0.9

    def remember(self, state, action, reward, next_state, done) -> None:
        self.memory.append((state, action, reward, next_state, done))

    def update(self) -> float:
        batch = random.sample(self.memory, BATCH)
        states, actions, rewards, next_states, dones = zip(*batch, strict=True)
        states = torch.tensor(np.array(states), dtype=torch.float32)
        states = states.permute(0, 3, 1, 2).contiguous() / 255.0
        next_states = torch.tensor(np.array(next_states), dtype=torch.float32)
        next_states = next_states.permute(0, 3, 1, 2).contiguous() / 255.0
        actions = torch.tensor(actions, dtype=torch.int64)
        rewards = torch.tensor(rewards, dtype=torch.float32)
        dones = torch.tensor(dones, dtype=torch.float32)
        with torch.no_grad():
            targets = rewards + self.gamma * self.net(next_states).max(1).values * (1 - dones)
        q = self.net(states).gather(1, actions.unsqueeze(1)).squeeze(1)
        loss = F.mse_loss(q, targets)
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return loss.item()


class CarefulDQN:
    """The DQN update as a careful PyTorch user writes it: the same `QNetwork`, channels-
    last memory format, `torch.autocast` with bfloat16 where the device runs it natively,
    uint8 frames in one preallocated tensor on the device, converted after indexing."""

    def __init__(self, frames: list[np.ndarray], seed: int = 0) -> None:
        from learner.device import conv_dtype
        from learner.network import QNetwork

        torch.manual_seed(seed)
        self.net = QNetwork().to(memory_format=torch.channels_last)
        self.optimizer = torch.optim.RMSprop(self.net.parameters(), lr=1e-3, alpha=0.9, eps=1e-7)
        self.dtype = conv_dtype("auto", torch.device("cpu"))
        self.frames = torch.from_numpy(np.stack(frames)).permute(0, 3, 1, 2)  # uint8 NCHW view
        self.frames = self.frames.contiguous(memory_format=torch.channels_last)
        n = len(frames) - 1
        rng = np.random.default_rng(seed)
        self.actions = torch.from_numpy(np.arange(n) % 4)
        self.rewards = torch.from_numpy(rng.choice([0.0, 0.4, -0.01, -1.0], n).astype(np.float32))
        self.dones = torch.from_numpy((np.arange(n) % 40 == 39).astype(np.float32))
        self.rng = rng
        self.gamma = 0.9

    def _images(self, index: torch.Tensor) -> torch.Tensor:
        return self.frames.index_select(0, index).float().div_(255.0)

    def update(self) -> float:
        rows = torch.from_numpy(self.rng.choice(len(self.actions), BATCH, replace=False))
        autocast = torch.autocast("cpu", dtype=torch.bfloat16, enabled=self.dtype != torch.float32)
        with torch.no_grad(), autocast:
            next_q = self.net(self._images(rows + 1)).float().max(1).values
        targets = self.rewards[rows] + self.gamma * next_q * (1 - self.dones[rows])
        with autocast:
            q = self.net(self._images(rows)).float()
        taken = q.gather(1, self.actions[rows].unsqueeze(1)).squeeze(1)
        loss = F.mse_loss(taken, targets)
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return loss.item()


def real_frames(count: int, seed: int = 0) -> list[np.ndarray]:
    """Observations of random play in the fast simulator (content does not change speed,
    but these are what the learner sees)."""
    import sim

    env = sim.SortingEnv(motion="fast")
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    frames = [obs]
    while len(frames) < count:
        obs, _, terminated, truncated, _ = env.step(int(rng.integers(4)))
        frames.append(obs)
        if terminated or truncated:
            obs, _ = env.reset(seed=int(rng.integers(2**31)))
            frames.append(obs)
    env.close()
    return frames[:count]


def bench_update(threads: int, repeats: int, block: int, frames: list[np.ndarray]) -> dict:
    from learner.agent import DQNAgent
    from learner.config import DQNConfig
    from learner.replay import ReplayMemory

    torch.set_num_threads(threads)
    rng = np.random.default_rng(0)
    random.seed(0)
    reference = ReferenceDQN()
    careful = CarefulDQN(frames)
    agent = DQNAgent(DQNConfig(torch_threads=threads, conv_kernel="none"), torch.device("cpu"))
    kernel = kernel_name(agent.dtype)
    compiled = (
        DQNAgent(DQNConfig(torch_threads=threads, conv_kernel=kernel), torch.device("cpu"))
        if kernel != "none"
        else None
    )
    memory = ReplayMemory(len(frames), agent.frame_shape)
    for t in range(len(frames) - 1):
        done = t % 40 == 39
        reward = float(rng.choice([0.0, 0.4, -0.01, -1.0]))
        reference.remember(frames[t], t % 4, reward, frames[t + 1], done)
        memory.add(agent.encode(frames[t]), t % 4, reward, agent.encode(frames[t + 1]), done, False)

    def learner_update() -> float:
        return agent.update(memory.sample(BATCH, rng))

    def compiled_update() -> float:
        assert compiled is not None
        return compiled.update(memory.sample(BATCH, rng))

    times: dict[str, list[float]] = {"reference": [], "careful": [], "learner": [], "kernels": []}
    ratios: dict[str, list[float]] = {"reference": [], "careful": [], "kernels": []}
    contenders = [reference.update, careful.update, learner_update]
    if compiled is not None:
        contenders.append(compiled_update)
    for update in contenders:
        for _ in range(3):
            update()  # warm-up: allocator, oneDNN kernels
    for _ in range(repeats):
        ref = _time_block(reference.update, block)
        best_plain = _time_block(careful.update, block)
        fast = _time_block(learner_update, block)
        times["reference"].append(ref)
        times["careful"].append(best_plain)
        times["learner"].append(fast)
        ratios["reference"].append(ref / fast)
        ratios["careful"].append(best_plain / fast)
        if compiled is not None:
            own = _time_block(compiled_update, block)
            times["kernels"].append(own)
            ratios["kernels"].append(fast / own)
    kernels = (
        {
            "kernel": kernel,
            "kernels_ms": 1000 * statistics.median(times["kernels"]),
            "speedup_kernels": statistics.median(ratios["kernels"]),
            "speedup_kernels_range": (min(ratios["kernels"]), max(ratios["kernels"])),
            "kernels_vs_reference": statistics.median(
                r / k for r, k in zip(times["reference"], times["kernels"], strict=True)
            ),
            "kernels_gflops": update_flop(agent.network, BATCH)
            / statistics.median(times["kernels"])
            / 1e9,
        }
        if compiled is not None
        else {"kernel": "none"}
    )
    return kernels | {
        "threads": threads,
        "reference_ms": 1000 * statistics.median(times["reference"]),
        "careful_ms": 1000 * statistics.median(times["careful"]),
        "learner_ms": 1000 * statistics.median(times["learner"]),
        "speedup": statistics.median(ratios["reference"]),
        "speedup_range": (min(ratios["reference"]), max(ratios["reference"])),
        "speedup_careful": statistics.median(ratios["careful"]),
        "speedup_careful_range": (min(ratios["careful"]), max(ratios["careful"])),
        "conv_dtype": str(agent.dtype).replace("torch.", ""),
    }


def update_flop(network: torch.nn.Module, batch: int) -> float:
    """The network's own FLOPs in one update (`_conv_flop`'s count): each layer forward on
    the batch and its next states, backward on the batch (the weights' gradient, and the
    input's but for the first convolution); the dense layers the same."""
    from learner.network import QNetwork

    assert isinstance(network, QNetwork), "the paper's network for images"
    side, _, _ = network.image_shape
    flop = 0.0
    for index, conv in enumerate(network.convs):
        out_c, in_c, k, _ = conv.weight.shape
        one = 2.0 * batch * side * side * out_c * in_c * k * k
        flop += 2 * one + (one if index == 0 else 2 * one)
        side //= 2
    for dense in (network.dense, network.out):
        one = 2.0 * batch * dense.in_features * dense.out_features
        flop += 2 * one + 2 * one
    return flop


def kernel_name(dtype: torch.dtype) -> str:
    """The compiled convolutions for all three layers in the precision of `dtype`, where
    they run here (`make kernels`, the CPU's flags), else `none`."""
    from learner import machine

    precision = "bf16" if dtype == torch.bfloat16 else "fp32"
    for variant, (_, variant_precision) in machine.CONV_KERNEL_VARIANTS.items():
        name = machine.conv_kernel_name(variant, machine.CONV_KERNEL_LAYERS)
        if variant_precision == precision and machine.conv_kernel_runs(name):
            return name
    return "none"


EXPERIMENT_UPDATES = 140_739
"""Updates of the paper's experiment: 10 autonomous runs, the advisor, 10 agent-advised
(the replication's arm B, `docs/results/replication-2/`)."""


def _part(name: str, shapes: list[list[int]]) -> str:
    if name == "aten::mkldnn_convolution":
        return f"conv {tuple(shapes[1])} forward"
    if name == "aten::convolution_backward":
        return f"conv {tuple(shapes[2])} backward"
    if name in ("aten::copy_", "aten::fill_", "aten::zero_", "aten::clone", "aten::contiguous"):
        return "layout copies and fills"
    if name in ("aten::addmm", "aten::mm"):
        return "dense layers"
    if name in (
        "aten::sub", "aten::mul", "aten::maximum", "aten::threshold_backward", "aten::sign_",
        "aten::clamp_min_", "aten::relu_", "aten::add_", "aten::sum",
    ):  # fmt: skip
        return "element-wise (phase max-pool, ReLU, their gradients)"
    return "rest (optimizer, loss, indexing, autograd)"


def _conv_flop(part: str, batch: int) -> float:
    """FLOPs of one update's calls of a convolution part (its forward runs on the batch
    and its next states; its backward on the batch, the first layer's without the input's
    gradient)."""
    out_c, in_c, k, _ = (int(v) for v in part.split("(")[1].split(")")[0].split(", "))
    side = {12: 32, 16: 16, 32: 8}[in_c]  # the space-to-depth layers' output sides
    one = 2.0 * batch * side * side * out_c * in_c * k * k
    if part.endswith("forward"):
        return 2 * one
    return one if in_c == 12 else 2 * one


def matmul_rate(dtype: torch.dtype, size: int = 2048, repeats: int = 7) -> float:
    """The core's matrix-multiply rate in GFLOPS (one thread, a size x size `torch.matmul`,
    median of `repeats`): what the update's convolutions are held against."""
    torch.set_num_threads(1)
    a = torch.randn(size, size).to(dtype)
    b = torch.randn(size, size).to(dtype)
    torch.matmul(a, b)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        torch.matmul(a, b)
        times.append(time.perf_counter() - start)
    return 2.0 * size**3 / statistics.median(times) / 1e9


def bench_profile(rounds: int, block: int, frames: list[np.ndarray]) -> dict:
    """The learner's update by part (one thread), medians over `rounds` profiled blocks."""
    from torch.profiler import ProfilerActivity, profile

    from learner.agent import DQNAgent
    from learner.config import DQNConfig
    from learner.replay import ReplayMemory

    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    agent = DQNAgent(DQNConfig(torch_threads=1), torch.device("cpu"))
    memory = ReplayMemory(len(frames), agent.frame_shape)
    for t in range(len(frames) - 1):
        memory.add(agent.encode(frames[t]), t % 4, 0.0, agent.encode(frames[t + 1]), False, False)
    batches = [memory.sample(BATCH, rng) for _ in range(block)]
    for b in batches[:3]:
        agent.update(b)
    parts: dict[str, list[float]] = {}
    walls: list[float] = []
    for _ in range(rounds):
        start = time.perf_counter()
        with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as prof:
            for b in batches:
                agent.update(b)
        walls.append(1000 * (time.perf_counter() - start) / block)
        totals: dict[str, float] = {}
        for event in prof.key_averages(group_by_input_shape=True):
            part = _part(event.key, event.input_shapes)
            totals[part] = totals.get(part, 0.0) + event.self_cpu_time_total / 1000 / block
        for part, ms in totals.items():
            parts.setdefault(part, []).append(ms)
    medians = {part: statistics.median(ms) for part, ms in parts.items()}
    return {
        "matmul_gflops": matmul_rate(agent.dtype),
        "conv_dtype": str(agent.dtype).replace("torch.", ""),
        "update_ms": statistics.median(walls),
        "update_ms_range": (min(walls), max(walls)),
        "parts": dict(sorted(medians.items(), key=lambda kv: -kv[1])),
    }


def print_profile(r: dict) -> None:
    low, high = r["update_ms_range"]
    print(
        f"  one update, 1 thread, {r['conv_dtype']} convs: {r['update_ms']:.1f} ms under the "
        f"profiler (rounds {low:.1f}-{high:.1f}); by part, ms per update:"
    )
    conv_ms = 0.0
    for part, ms in r["parts"].items():
        rate = ""
        if part.startswith("conv"):
            conv_ms += ms
            rate = f"  {_conv_flop(part, BATCH) / ms / 1e6:6.1f} GFLOPS"
        print(f"    {part:58} {ms:6.1f}{rate}")
    share = conv_ms / sum(r["parts"].values())
    bound = EXPERIMENT_UPDATES * conv_ms / 1000 / 2 / 60
    flop = sum(_conv_flop(part, BATCH) for part in r["parts"] if part.startswith("conv"))
    print(
        f"  the convolutions: {conv_ms:.1f} ms ({share:.0%} of the profiled time) at "
        f"{flop / conv_ms / 1e6:.1f} GFLOPS, against the core's {r['conv_dtype']} matmul rate "
        f"of {r['matmul_gflops']:.1f} GFLOPS (2048x2048, 1 thread); at this rate the paper's "
        f"experiment's {EXPERIMENT_UPDATES:,} updates need {bound:.0f} min of the 2 cores for "
        "them alone"
    )


def _time_block(update: Callable[[], float], block: int) -> float:
    start = time.perf_counter()
    for _ in range(block):
        update()
    return (time.perf_counter() - start) / block


def bench_run(threads: int, training_steps: int) -> dict:
    """Time a paper-config autonomous run: all of pretraining, then `training_steps`."""
    import sim
    from learner import DQNConfig, Trainer

    env = sim.SortingEnv(motion="fast")
    trainer = Trainer(env, DQNConfig(torch_threads=threads), seed=0)
    start = time.perf_counter()
    while trainer.stage == "pretrain":
        trainer.step()
    pretraining = time.perf_counter() - start
    start = time.perf_counter()
    for _ in range(training_steps):
        trainer.step()
    per_step = (time.perf_counter() - start) / training_steps
    env.close()
    return {
        "threads": threads,
        "pretraining_s": pretraining,
        "training_step_ms": 1000 * per_step,
        "episodes_seen": trainer.episodes_done["train"],
        "paper_run_min": (pretraining + per_step * PAPER_TRAINING_STEPS) / 60,
    }


def footprint() -> dict:
    """Resident memory (MB) along a trainer's life: imports, an empty memory, a full one,
    and after updates (autograd's working set, kernels' code pages)."""
    import sim
    from learner import DQNConfig, Trainer

    stages = {"imports": _rss()}
    frames = real_frames(500)
    trainer = Trainer(sim.SortingEnv(motion="fast"), DQNConfig(), seed=0)
    stages["trainer, empty memory"] = _rss()
    agent, memory = trainer.agent, trainer.memory
    packed = [agent.encode(frame) for frame in frames]
    for t in range(memory.capacity):
        done = t % 50 == 49
        memory.add(packed[t % 499], t % 4, 0.0, packed[t % 499 + 1], done, t % 250 == 249)
    stages[f"{len(memory):,} transitions"] = _rss()
    rng = np.random.default_rng(0)
    for _ in range(5):
        agent.update(memory.sample(BATCH, rng))
    stages["after updates"] = _rss()
    return {"stages": stages, "memory_mb": memory.nbytes / 2**20}


def _rss() -> dict[str, float]:
    fields = {}
    with open("/proc/self/status") as status:
        for line in status:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "RssAnon"):
                fields[key] = int(value.split()[0]) / 1024
    return {"rss": fields.get("VmRSS", 0.0), "anon": fields.get("RssAnon", 0.0)}


def curves(episodes: int, seeds: Sequence[int]) -> Path:
    """Fast vs plain update, the same oracle-advised runs otherwise, to a PNG."""
    import sim
    from learner import DQNConfig, Trainer, make_advisor
    from learner.recording import learning_curve_figure

    # the paper's hyperparameters (batch 128, memory 20,000, 1,000 pretraining steps, the
    # last 100 advised), but exploration ends after ~460 updates instead of ~9,200 and
    # episodes stop at 60 steps, so that a short run shows the whole learning curve
    results: dict[str, list[list[float]]] = {"fast": [], "plain": []}
    for seed in seeds:
        for update in ("fast", "plain"):
            config = DQNConfig(
                episodes=episodes, epsilon_decay=0.99, max_episode_steps=60, update=update
            )
            env = sim.SortingEnv(motion="fast", max_episode_steps=60)
            trainer = Trainer(env, config, make_advisor("oracle", seed=seed), seed=seed)
            start = time.perf_counter()
            rewards = [e.collected_reward for e in trainer.run()]
            results[update].append(rewards)
            print(
                f"  seed {seed} {update:5}: {time.perf_counter() - start:6.0f} s, "
                f"R_T {sum(rewards):7.2f}, last 10 mean {np.mean(rewards[-10:]):.2f}",
                flush=True,
            )
            env.close()
    figure = learning_curve_figure(
        {
            f"{name} update (mean of {len(runs)} seeds)": list(np.mean(runs, axis=0))
            for name, runs in results.items()
        },
        title=f"Fast vs plain float32 update, oracle early advising, {episodes} episodes",
    )
    CURVES_PNG.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(CURVES_PNG, dpi=120)
    (CURVES_PNG.with_suffix(".json")).write_text(json.dumps(results) + "\n")
    return CURVES_PNG


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_learner")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=7, help="block pairs for the update")
    parser.add_argument("--block", type=int, default=5, help="updates per timed block")
    parser.add_argument("--run-steps", type=int, default=2000, help="training steps timed")
    parser.add_argument("--curves", type=int, default=0, metavar="EPISODES")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--footprint", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--profile", action="store_true", help="the update by part only")
    parser.add_argument("--rounds", type=int, default=7, help="profiled blocks (--profile)")
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore", message="Using padding='same' with even kernel")
    if args.footprint:
        print(json.dumps(footprint()))
        return
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs", flush=True)

    frames = real_frames(5000)
    if args.profile:
        print(f"\nthe update by part, batch {BATCH}, median of {args.rounds} profiled blocks")
        print_profile(bench_profile(args.rounds, args.block, frames))
        print(f"load average {os.getloadavg()[0]:.1f} at the end", flush=True)
        return
    print(f"\nupdate, batch {BATCH} (median of {args.repeats} pairs of {args.block}-update blocks)")
    from learner.device import conv_dtype

    kernel_rates = []
    for threads in args.threads:
        r = bench_update(threads, args.repeats, args.block, frames)
        if r["kernel"] != "none":
            kernel_rates.append((threads, r["kernels_gflops"]))
        low, high = r["speedup_range"]
        c_low, c_high = r["speedup_careful_range"]
        print(
            f"  {threads} thread(s): learner {r['learner_ms']:5.1f} ms ({r['conv_dtype']} "
            f"convs); plain reference {r['reference_ms']:6.1f} ms: {r['speedup']:.2f}x faster "
            f"(pairs {low:.2f}x-{high:.2f}x); careful PyTorch (autocast {r['conv_dtype']}, "
            f"channels-last) {r['careful_ms']:6.1f} ms: {r['speedup_careful']:.2f}x faster "
            f"(pairs {c_low:.2f}x-{c_high:.2f}x)",
            flush=True,
        )
        if r["kernel"] != "none":
            low, high = r["speedup_kernels_range"]
            print(
                f"    with the compiled convolutions ({r['kernel']}): {r['kernels_ms']:5.1f} ms, "
                f"{r['speedup_kernels']:.2f}x the learner's PyTorch update (pairs {low:.2f}x-"
                f"{high:.2f}x), {r['kernels_vs_reference']:.2f}x the plain reference; the "
                f"network's own FLOPs at {r['kernels_gflops']:.0f} GFLOPS",
                flush=True,
            )
    dtype = conv_dtype("auto", torch.device("cpu"))
    rate = matmul_rate(dtype)
    print(
        f"  the core's {str(dtype).replace('torch.', '')} matrix-multiply rate (one thread, "
        f"same run): {rate:.0f} GFLOPS"
        + "".join(
            f"; the compiled update reaches {gflops / rate:.0%} of it with {threads} thread(s)"
            for threads, gflops in kernel_rates
        ),
        flush=True,
    )

    print(f"\npaper-scale run: 1,000 pretraining + {PAPER_TRAINING_STEPS:,} training steps")
    for threads in args.threads:
        r = bench_run(threads, args.run_steps)
        print(
            f"  {threads} thread(s): pretraining {r['pretraining_s']:.0f} s, "
            f"{r['training_step_ms']:.1f} ms per training step (env + act + update, "
            f"{args.run_steps} steps): about {r['paper_run_min']:.0f} min per run",
            flush=True,
        )

    command = [sys.executable, "-m", "benchmarks.bench_learner", "--footprint"]
    result = subprocess.run(command, capture_output=True, text=True, check=True)
    r = json.loads(result.stdout.strip().splitlines()[-1])
    print(f"\nresident memory (fresh process; the replay memory holds {r['memory_mb']:.0f} MiB)")
    for stage, mb in r["stages"].items():
        print(f"  {stage:24} {mb['rss']:5.0f} MiB resident, {mb['anon']:5.0f} MiB anonymous")
    if args.curves:
        print(f"\nlearning curves, {args.curves} episodes, seeds {args.seeds}:", flush=True)
        print(f"  wrote {curves(args.curves, args.seeds)}")


if __name__ == "__main__":
    main()
