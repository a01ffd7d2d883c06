"""The default population size: a stated rule of the device, the CPU kind, the cores and
the memory (`server.worker.population.default_population`)."""

from __future__ import annotations

from learner import machine
from learner.run import FRAME_BYTES, RunSpec
from server.worker.population import (
    POPULATION_BF16,
    POPULATION_CPU,
    POPULATION_CUDA,
    default_population,
)


def run(**config: object) -> RunSpec:
    return RunSpec.from_json({"config": {"torch_threads": 1, **config}})


def test_the_device_and_the_cpu_kind_decide_the_size() -> None:
    assert default_population(run(device="cuda"), cores=2) == POPULATION_CUDA
    cpu = POPULATION_BF16 if machine.bf16_native_cpu() else POPULATION_CPU
    assert default_population(run(device="cpu"), cores=2) == cpu
    assert POPULATION_CUDA > POPULATION_BF16 > POPULATION_CPU > 1


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
