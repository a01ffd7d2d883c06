"""`RunSpec`: one description of a run, its rules checked once, built into env and trainer."""

from __future__ import annotations

import pytest

from learner import machine
from learner.config import DQNConfig
from learner.fields import FieldError
from learner.run import STRATEGY_OPTIONS, RunSpec, RunSpecError, StrategyOptions, from_old_settings

SMALL = DQNConfig.preset("paper", pretraining_steps=30, advice_budget=10, batch_size=8)


def test_strategy_options_come_from_the_strategies_constructors() -> None:
    assert STRATEGY_OPTIONS == {
        "early": {},
        "alternating": {"interval": 2},
        "importance": {"threshold": 0.1},
        "mistake_correcting": {"threshold": 0.1},
    }


@pytest.mark.parametrize(
    ("changes", "field", "message"),
    [
        ({"config": SMALL.replace(advice_budget=31)}, "config.advice_budget", "its 31 advice"),
        ({"strategy": "importance"}, "strategy", "only an agent advisor has"),
        (
            {"strategy_options": StrategyOptions(interval=3)},
            "strategy_options.interval",
            "takes no option interval",
        ),
        ({"method": "agent"}, "advisor_checkpoint", "needs advisor_checkpoint"),
        ({"sort_rule": "size"}, "sort_rule", "color, shape, or a map"),
    ],
)
def test_validate_names_the_field_to_change(
    changes: dict[str, object], field: str, message: str
) -> None:
    spec = RunSpec(**{"config": SMALL, "method": "oracle", **changes})  # type: ignore[arg-type]
    with pytest.raises(RunSpecError, match=message) as raised:
        spec.validate()
    assert raised.value.field == field


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"motion": "slow"}, "motion"),
        ({"strategy_options": {"interval": 0}}, "strategy_options.interval"),
        ({"config": {"batch_size": 10**400}}, "config.batch_size"),
        ({"scenario": {"knock_off_rate": float("nan")}}, "scenario.knock_off_rate"),
        ({"nosuch": 1}, "nosuch"),
    ],
)
def test_from_json_names_the_field_and_its_range_never_the_value(
    data: dict[str, object], field: str
) -> None:
    with pytest.raises(FieldError) as raised:
        RunSpec.from_json(data)
    assert raised.value.field == field
    assert "10000000000" not in str(raised.value) and "nan" not in str(raised.value).lower()


def test_build_gives_the_trainer_the_strategys_options() -> None:
    spec = RunSpec(
        config=SMALL,
        method="oracle",
        strategy="alternating",
        strategy_options=StrategyOptions(interval=3),
    )
    trainer, env = spec.build()
    try:
        assert trainer.strategy is not None and trainer.strategy.options() == {"interval": 3}
        assert trainer.strategy.budget == 10
    finally:
        env.close()


def test_the_stored_document_reads_back_and_old_checkpoint_metadata_still_reads() -> None:
    spec = RunSpec(config=SMALL, method="random", strategy="alternating").validate().pinned()
    assert RunSpec.from_json(spec.to_json()) == spec
    old = {  # what ideeprl train stored before RunSpec
        "advisor": "random", "advisor_checkpoint": None, "error_rate": 0.0,
        "strategy": "alternating", "budget": 10, "interval": 4, "threshold": 0.1,
        "motion": "fast", "sort_rule": "color", "seed": 0, "preset": "paper",
    }  # fmt: skip
    back = from_old_settings(old, SMALL).validate()
    assert back.method == "random" and back.advice_budget == 10
    assert back.strategy_options.given() == {"interval": 4}
    assert back.scenario.reward_scheme == "paper"


def test_pinning_resolves_the_numerics_on_this_machine() -> None:
    pinned = RunSpec(config=SMALL).pinned()
    assert pinned.config.device in ("cpu", "cuda")
    assert pinned.config.torch_threads >= 1
    native = machine.bf16_native_cpu() or pinned.config.device == "cuda"
    assert pinned.config.precision == ("bf16" if native else "fp32")
    assert pinned.pinned() == pinned and pinned.numerics_problem() is None
    plain = RunSpec(config=SMALL.replace(update="plain")).pinned()
    assert plain.config.precision == "fp32"


def test_pinning_chooses_the_kernels_by_the_switch_the_cpu_and_the_run(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    if not machine.conv_kernel_runs("avx2"):
        pytest.skip("the AVX2 kernel does not run here (no AVX2, or `make kernels` not run)")
    fp32 = SMALL.replace(precision="fp32", device="cpu")
    monkeypatch.delenv(machine.CONV_KERNEL_SWITCH, raising=False)
    assert RunSpec(config=fp32).pinned().config.conv_kernel == "none"
    monkeypatch.setenv(machine.CONV_KERNEL_SWITCH, "on")
    pinned = RunSpec(config=fp32).pinned()
    assert pinned.config.conv_kernel == "avx2:1-3" and pinned.numerics_problem() is None
    assert RunSpec(config=fp32.replace(update="plain")).pinned().config.conv_kernel == "none"
    assert RunSpec(config=fp32.replace(conv_kernel="none")).pinned().config.conv_kernel == "none"
    monkeypatch.setattr(machine, "cpu_flags", lambda: frozenset({"sse2"}))
    assert "avx2 variant" in (pinned.numerics_problem() or "")
    assert pinned.repinned().config.conv_kernel == "none"


def test_the_pinned_kernel_names_the_layers_it_computes() -> None:
    """A bare variant is the first layer alone (what it computed when runs were pinned to
    it), a suffix names the layers; the names and their parts go both ways."""
    assert machine.conv_kernel_parts("avx2") == ("avx2", frozenset({1}))
    assert machine.conv_kernel_parts("avx512bf16:1-3") == ("avx512bf16", frozenset({1, 2, 3}))
    assert machine.conv_kernel_parts("avx2:1,3") == ("avx2", frozenset({1, 3}))
    for name in ("avx2", "avx2:1-3", "avx512bf16:1-3", "avx2:1,3"):
        assert machine.conv_kernel_name(*machine.conv_kernel_parts(name)) == name
    assert machine.conv_kernel_layers_computed("avx2")
    assert machine.conv_kernel_layers_computed("avx2:1-3")
    assert not machine.conv_kernel_layers_computed("avx2:1,3")


def test_a_run_pinned_to_other_compiled_layers_than_this_code_computes_is_not_resumed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A run pinned to the first layer's kernel alone (`avx2`) resumes as pinned where this
    code computes that layer set; where it does not, the reason names the layers, and a
    re-pin takes the layers a run pinned here takes."""
    if not machine.conv_kernel_runs("avx2"):
        pytest.skip("the AVX2 kernel does not run here (no AVX2, or `make kernels` not run)")
    monkeypatch.setenv(machine.CONV_KERNEL_SWITCH, "on")
    first = RunSpec(config=SMALL.replace(precision="fp32", device="cpu", conv_kernel="avx2"))
    assert first.pinned().config.conv_kernel == "avx2" and first.numerics_problem() is None
    monkeypatch.setattr(machine, "CONV_KERNEL_LAYER_SETS", (frozenset({1, 2, 3}),))
    problem = first.numerics_problem() or ""
    assert "layers 1 (conv_kernel avx2)" in problem and "layers 1, 2, 3" in problem
    repinned = first.repinned().config  # the layers and precision a run pinned here takes
    assert repinned.conv_kernel == machine.conv_kernel_for(repinned.precision)
    assert machine.conv_kernel_parts(repinned.conv_kernel)[1] == frozenset({1, 2, 3})
    assert first.repinned().numerics_problem() is None


def test_a_kernel_is_pinned_only_where_it_computes_the_run() -> None:
    with pytest.raises(RunSpecError, match="fast update") as raised:
        RunSpec(config=SMALL.replace(update="plain", conv_kernel="avx2")).validate()
    assert raised.value.field == "config.conv_kernel"
    with pytest.raises(RunSpecError, match="computes bf16"):
        RunSpec(config=SMALL.replace(precision="fp32", conv_kernel="avx512bf16")).validate()
    RunSpec(config=SMALL.replace(precision="fp32", conv_kernel="avx2")).validate()
    with pytest.raises(RunSpecError, match="computes bf16"):
        RunSpec(config=SMALL.replace(precision="fp32", conv_kernel="avx512bf16:1-3")).validate()
    RunSpec(config=SMALL.replace(precision="fp32", conv_kernel="avx2:1-3")).validate()


def test_a_replay_memory_larger_than_the_machine_is_refused_before_anything_runs() -> None:
    spec = RunSpec(config=SMALL.replace(memory_size=10_000_000))
    with pytest.raises(RunSpecError, match="GiB") as raised:
        spec.check_memory(total=8 * 2**30)
    assert raised.value.field == "config.memory_size"
    spec.replace(config=SMALL).check_memory(total=8 * 2**30)


def test_torch_and_the_machine_agree_on_bfloat16() -> None:
    import torch

    from learner.device import bf16_native

    assert bf16_native(torch.device("cpu")) == machine.bf16_native_cpu()
