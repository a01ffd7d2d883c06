"""The compiled convolutions (`learner.conv_kernel`) against the PyTorch path, in one run.

    python -m benchmarks.bench_conv_kernel            # both precisions this CPU runs
    python -m benchmarks.bench_conv_kernel --blocks 9

1. The first layer alone, as one update uses it: forward on 256 frames (the batch and its
   next states), backward (weight and bias) on 128; the fast update's space-to-depth
   layer against the kernel, blocks of each alternating, with the kernel's rate against
   the core's matrix-multiply rate measured in the same run.
2. The second and third layers alone, the same way (forward on 256, backward with the
   input's gradient on 128), PyTorch's phase layer against the kernel.
3. The whole update (batch 128, one thread): plain, and with the first layer compiled,
   the first and third, all three, the same network and batches, blocks in turn.

Times are medians of blocks: CPU time of this thread (what the work costs, less
disturbed by other processes on a shared machine) and wall time; ratios per block pair.
The machine's load is printed beside them.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
import torch
import torch.nn.functional as F

BATCH = 128
LAYER_FLOP = 2.0 * 64 * 64 * 4 * 3 * 8 * 8
"""FLOPs of the first convolution on one image (forward; the weight gradient the same)."""


def _time(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    """(thread CPU ms, wall ms) per call of `fn`."""
    cpu, wall = time.thread_time(), time.perf_counter()
    for _ in range(repeats):
        fn()
    return (
        1000 * (time.thread_time() - cpu) / repeats,
        1000 * (time.perf_counter() - wall) / repeats,
    )


def _compare(
    name: str, a: Callable[[], object], b: Callable[[], object], blocks: int, repeats: int
) -> dict[str, float]:
    for _ in range(2):
        a()
        b()
    ta, tb = [], []
    for _ in range(blocks):
        ta.append(_time(a, repeats))
        tb.append(_time(b, repeats))
    ratios = [x[0] / y[0] for x, y in zip(ta, tb, strict=True)]
    result = {
        "torch_cpu_ms": statistics.median(t[0] for t in ta),
        "kernel_cpu_ms": statistics.median(t[0] for t in tb),
        "torch_wall_ms": statistics.median(t[1] for t in ta),
        "kernel_wall_ms": statistics.median(t[1] for t in tb),
        "ratio": statistics.median(ratios),
        "ratio_min": min(ratios),
        "ratio_max": max(ratios),
    }
    print(
        f"  {name}: PyTorch {result['torch_cpu_ms']:.2f} ms, kernel "
        f"{result['kernel_cpu_ms']:.2f} ms of CPU ({result['torch_wall_ms']:.2f} / "
        f"{result['kernel_wall_ms']:.2f} wall): {result['ratio']:.2f}x "
        f"(pairs {result['ratio_min']:.2f}-{result['ratio_max']:.2f})"
    )
    return result


def matmul_rate(dtype: torch.dtype, size: int = 2048, repeats: int = 5) -> float:
    """GFLOPS of a size x size matmul, one thread, best of `repeats` in thread CPU time."""
    a, b = torch.randn(size, size).to(dtype), torch.randn(size, size).to(dtype)
    torch.matmul(a, b)
    best = min(_time(lambda: torch.matmul(a, b), 1)[0] for _ in range(repeats))
    return 2.0 * size**3 / (best / 1000) / 1e9


def bench_layer(precision: str, frames: torch.Tensor, blocks: int) -> None:
    from learner import conv_kernel
    from learner.network import QNetwork
    from learner.phase_conv import (
        PhaseConvForward,
        channels_last,
        phase_max_bias_relu,
        space_to_depth,
    )

    kernel = conv_kernel.load(precision)
    assert kernel is not None
    network = QNetwork()
    fast = PhaseConvForward(network, kernel.dtype)
    conv = network.conv1
    assert conv.bias is not None
    batch, next_batch = frames[:BATCH], frames[BATCH : 2 * BATCH]

    def torch_layer(x: torch.Tensor) -> torch.Tensor:
        kernel_weight, bias = fast.weights()[0]
        s, pad = space_to_depth(x, True, fast.layouts[0], kernel.dtype)
        return phase_max_bias_relu(channels_last(F.conv2d(s, kernel_weight, padding=pad)), bias)

    def kernel_layer(x: torch.Tensor) -> torch.Tensor:
        assert conv.bias is not None
        return conv_kernel.first_layer(kernel, x, conv.weight, conv.bias)

    def as_in_an_update(layer: Callable[[torch.Tensor], torch.Tensor]) -> Callable[[], None]:
        def run() -> None:
            with torch.no_grad():
                layer(next_batch)
            layer(batch).float().sum().backward()

        return run

    result = _compare(
        "first layer, one update's share",
        as_in_an_update(torch_layer),
        as_in_an_update(kernel_layer),
        blocks,
        3,
    )
    flop = 3 * BATCH * LAYER_FLOP
    rate = matmul_rate(kernel.dtype)
    kernel_rate = flop / (result["kernel_cpu_ms"] / 1000) / 1e9
    print(
        f"  the kernel: {kernel_rate:.0f} GFLOPS of the layer's own FLOPs, "
        f"{100 * kernel_rate / rate:.0f} % of the core's {precision} matmul rate "
        f"({rate:.0f} GFLOPS, same run)"
    )


def bench_later_layers(precision: str, blocks: int) -> None:
    from learner import conv_kernel
    from learner.network import QNetwork
    from learner.phase_conv import (
        PhaseConvForward,
        channels_last,
        phase_max_bias_relu,
        space_to_depth,
    )

    kernels = conv_kernel.load(precision)
    assert kernels is not None
    dtype = kernels.dtype
    network = QNetwork()
    fast = PhaseConvForward(network, dtype)
    inputs = {
        2: torch.rand(2 * BATCH, 16, 16, 16).to(dtype).permute(0, 3, 1, 2),
        3: torch.rand(2 * BATCH, 16, 16, 8).to(dtype).permute(0, 3, 1, 2),
    }
    for layer, x in inputs.items():
        conv = network.convs[layer - 1]
        assert conv.bias is not None

        def torch_layer(given: torch.Tensor, layer: int = layer) -> torch.Tensor:
            kernel_weight, bias = fast.weights()[layer - 1]
            layout = fast.layouts[layer - 1]
            if layer == 2:  # the first kernel's output is this layer's input as it is
                s, pad = given, layout.pad_before // 2
            else:
                s, pad = space_to_depth(given, False, layout, dtype)
            return phase_max_bias_relu(channels_last(F.conv2d(s, kernel_weight, padding=pad)), bias)

        def kernel_layer(given: torch.Tensor, layer: int = layer) -> torch.Tensor:
            conv = network.convs[layer - 1]
            assert conv.bias is not None
            return conv_kernel.later_layer(kernels, layer, given, conv.weight, conv.bias)

        def as_in_an_update(
            run_layer: Callable[[torch.Tensor], torch.Tensor], x: torch.Tensor = x
        ) -> Callable[[], None]:
            def run() -> None:
                with torch.no_grad():
                    run_layer(x[BATCH:])
                given = x[:BATCH].detach().requires_grad_()
                run_layer(given).float().sum().backward()

            return run

        _compare(
            f"layer {layer}, one update's share",
            as_in_an_update(torch_layer),
            as_in_an_update(kernel_layer),
            blocks,
            3,
        )


LAYER_SETS = ((1,), (1, 3), (1, 2, 3))
"""The compiled layers each timed update takes (the rest in PyTorch)."""


def bench_update(precision: str, blocks: int) -> None:
    """The whole fast update, in PyTorch (the switch off) and with each of `LAYER_SETS`
    compiled, blocks of each in turn, the same network and batches; ratios to PyTorch's
    per round."""
    from benchmarks.bench_learner import real_frames
    from learner import conv_kernel
    from learner.agent import DQNAgent
    from learner.config import DQNConfig
    from learner.replay import ReplayMemory

    config = DQNConfig(torch_threads=1, precision=precision)
    previous = os.environ.get(conv_kernel.SWITCH)
    os.environ[conv_kernel.SWITCH] = "off"
    agents = {"PyTorch": DQNAgent(config, torch.device("cpu"))}
    os.environ[conv_kernel.SWITCH] = "on"
    for layers in LAYER_SETS:
        agent = DQNAgent(config, torch.device("cpu"))
        for fast in (agent._fast, agent._fast_target):
            if fast is not None and fast.conv_kernels is not None:
                fast.conv_kernels = dataclasses.replace(fast.conv_kernels, layers=frozenset(layers))
        agents["kernels " + "+".join(map(str, layers))] = agent
    if previous is None:
        del os.environ[conv_kernel.SWITCH]
    else:
        os.environ[conv_kernel.SWITCH] = previous
    plain = agents["PyTorch"]
    images = real_frames(1500)
    memory = ReplayMemory(len(images), plain.frame_shape)
    rng = np.random.default_rng(0)
    for t in range(len(images) - 1):
        reward = float(rng.choice([0.0, 0.4, -0.01, -1.0]))
        encoded = plain.encode(images[t]), plain.encode(images[t + 1])
        memory.add(encoded[0], t % 4, reward, encoded[1], t % 40 == 39, False)
    batches = [memory.sample(BATCH, rng) for _ in range(16)]
    for agent in agents.values():
        for batch in batches[:2]:
            agent.update(batch)
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in agents}
    for _ in range(blocks):
        for name, agent in agents.items():
            times[name].append(_time(lambda a=agent: [a.update(b) for b in batches[:4]], 1))
    plain_cpu = [t[0] / 4 for t in times["PyTorch"]]
    print("  the whole update (batch 128, one thread), median of blocks of 4:")
    for name, measured in times.items():
        cpu = [t[0] / 4 for t in measured]
        wall = statistics.median(t[1] / 4 for t in measured)
        ratios = [p / c for p, c in zip(plain_cpu, cpu, strict=True)]
        print(
            f"    {name}: {statistics.median(cpu):.2f} ms of CPU ({wall:.2f} wall), "
            f"{statistics.median(ratios):.2f}x PyTorch's "
            f"(rounds {min(ratios):.2f}-{max(ratios):.2f})"
        )


def main() -> None:
    from learner import conv_kernel

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--blocks", type=int, default=7)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"load (1, 5, 15 min): {os.getloadavg()}")
    rng = np.random.default_rng(0)
    frames = torch.from_numpy(rng.integers(0, 256, (2 * BATCH, 32, 32, 12), dtype=np.uint8))
    for precision in ("bf16", "fp32"):
        kernel = conv_kernel.load(precision)
        if kernel is None:
            print(f"{precision}: no kernel runs here (built? `make kernels`)")
            continue
        print(f"{precision} ({kernel.variant}):")
        bench_layer(precision, frames, args.blocks)
        bench_later_layers(precision, args.blocks)
        bench_update(precision, args.blocks)
    print(f"load (1, 5, 15 min): {os.getloadavg()}")


if __name__ == "__main__":
    main()
