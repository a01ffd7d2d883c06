"""A seeded run with the compiled convolutions (`learner.conv_kernel`, the float32 AVX2
variant for all three layers) takes the steps the PyTorch update takes: the same actions
from the same sources, the same rewards, outcomes and images, until the first step at
which the two networks rank the actions differently, and Q-values and losses within
float32's tolerance until then.

The run is the records fixture's autonomous run (`tests/learner/records.py`: the paper's
learner at a test's scale, float32, one thread, seed 11; 60 pretraining steps and 41
training steps with their updates). The tolerance is the one the kernels meet on a single
forward pass (`tests/learner/test_conv_kernel_layers.py`): rtol 1e-5 and atol 1e-5 times
the largest magnitude, here the step's largest Q-value and the run's largest loss so far.
Training carries the two float orders' rounding on in the weights, so the differences
grow with the updates (on the AVX-512 BF16 EPYC: 1e-7 of the largest Q-value before
training, 1.9e-5 after 41 updates); a step at which the two rank the actions otherwise
would send the runs apart, and past it nothing is compared.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from learner import machine
from learner.run import RunSpec
from tests.learner import records
from tests.learner.conftest import Recorder

KERNEL = "avx2:1-3"
"""The float32 variant for all three layers: the one that computes this run's function
(float32) on AVX2 CPUs and on AVX-512 ones."""
Q = ("q_grab", "q_move_right", "q_move_left", "q_drop")


def _run(conv_kernel: str) -> list[dict[str, Any]]:
    """Every step of the records fixture's autonomous run with `conv_kernel`."""
    config = {**records.CONFIG, "conv_kernel": conv_kernel}
    spec = RunSpec.from_json({"method": "autonomous", "seed": 11, "config": config}).validate()
    assert spec.config.conv_kernel == conv_kernel and spec.config.precision == "fp32"
    recorder = Recorder()
    env = spec.make_env()
    try:
        spec.make_trainer(env, spec.make_advisor(), [recorder]).run()
    finally:
        env.close()
    return [dataclasses.asdict(step) for step in recorder.steps]


def close(value: float, expected: float, largest: float) -> bool:
    """Within rtol 1e-5 and atol 1e-5 times `largest`, as `torch.testing.assert_close`
    sums them."""
    return abs(value - expected) <= 1e-5 * abs(expected) + 1e-5 * largest


def _ranking(step: dict[str, Any]) -> tuple[str, ...] | None:
    """The actions from the highest Q-value down (None where the step has none)."""
    if any(step[name] is None for name in Q):
        return None
    return tuple(sorted(Q, key=lambda name: -step[name]))


def first_ranked_otherwise(plain: list[dict[str, Any]], kernel: list[dict[str, Any]]) -> int:
    """The index of the first step at which the two runs' networks rank the actions
    differently, or the runs' length where they never do."""
    for index, (one, other) in enumerate(zip(plain, kernel, strict=True)):
        if _ranking(one) != _ranking(other):
            return index
    return len(plain)


def test_a_seeded_run_with_the_kernels_takes_the_steps_of_the_pytorch_update() -> None:
    if not machine.conv_kernel_runs(KERNEL):
        pytest.skip(f"the {KERNEL} kernels do not run here (no AVX2, or `make kernels` not run)")
    plain, kernel = _run("none"), _run(KERNEL)
    assert len(plain) == len(kernel) and len(plain) > records.CONFIG["pretraining_steps"]
    until = first_ranked_otherwise(plain, kernel)
    largest_loss = 0.0
    for one, other in zip(plain[:until], kernel[:until], strict=True):
        where = f"step {one['global_step']} ({one['stage']}; {machine.cpu_kind()})"
        assert {k: one[k] for k in records.EXACT} == {k: other[k] for k in records.EXACT}, where
        if _ranking(one) is not None:
            scale = max(abs(one[name]) for name in Q)
            for name in Q:
                assert close(other[name], one[name], scale), (where, name, other[name], one[name])
        assert (one["loss"] is None) == (other["loss"] is None), where
        if one["loss"] is not None:
            largest_loss = max(largest_loss, abs(one["loss"]))
            assert close(other["loss"], one["loss"], largest_loss), (
                where, "loss", other["loss"], one["loss"])  # fmt: skip
    trained = [step for step in plain[:until] if step["loss"] is not None]
    assert trained, "the runs part before the first update: nothing of training compared"
