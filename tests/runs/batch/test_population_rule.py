"""The default population size: a stated rule of the device, the CPU kind, the cores and
the memory (`runs.worker.population.default_population`)."""

from __future__ import annotations

from learner import machine
from learner.run import FRAME_BYTES, RunSpec
from runs.worker.population import (
    POPULATION_CPU,
    POPULATION_CUDA,
    default_population,
    next_group,
)


def run(**config: object) -> RunSpec:
    return RunSpec.from_json({"config": {"torch_threads": 1, **config}})


def test_the_device_and_the_cpu_kind_decide_the_size() -> None:
    assert default_population(run(device="cuda"), cores=2) == POPULATION_CUDA
    assert default_population(run(device="cpu"), cores=2) == POPULATION_CPU
    assert POPULATION_CUDA > POPULATION_CPU > 1


def test_the_memory_caps_it_and_one_always_runs() -> None:
    frames = machine.total_memory() // FRAME_BYTES  # a replay memory of the whole machine
    paper = default_population(run(device="cuda"), cores=2)
    # Each agent's frames a twentieth of the machine: fewer agents fit beside each other.
    big = default_population(run(device="cuda", memory_size=frames // 20), cores=2)
    assert 1 <= big < paper
    # More workers share the memory: each population is smaller.
    assert default_population(run(device="cuda", memory_size=frames // 20), cores=8) < big
    assert default_population(run(device="cuda", memory_size=frames // 20), workers=8) < big
    # One agent's frames fill the machine: a population of one (the run alone).
    whole = min(frames, 10_000_000)
    assert default_population(run(device="cuda", memory_size=whole), cores=2) == 1


def test_waiting_runs_spread_over_every_worker_and_mates_share_a_key() -> None:
    queue = [("paper", i) for i in range(10)] + [("authors", 0)]
    key = [run[0] for run in queue]
    # Ten mates, two workers: five now, five for the other worker when it frees.
    assert next_group(queue, key, population=8, workers=2) == queue[:5]
    assert next_group(queue, key, population=3, workers=2) == queue[:3]
    assert next_group(queue, key, population=8, workers=1) == queue[:8]
    assert next_group(queue[-1:], key[-1:], population=8, workers=2) == [("authors", 0)]
    assert next_group(queue, [None] * len(queue), population=8, workers=2) == queue[:1]  # alone
    assert next_group(queue, key, population=1, workers=2) == queue[:1]
