"""`RunSpec`: one description of a run, its rules checked once, built into env and trainer."""

from __future__ import annotations

import pytest

from learner.config import DQNConfig
from learner.run import STRATEGY_OPTIONS, RunSpec, RunSpecError

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
        ({"budget": 31}, "advice_budget", "early advising gives its 31 advice"),
        ({"strategy": "importance"}, "strategy", "only an 'agent' advisor has"),
        ({"strategy_options": {"interval": 3}}, "strategy_options", "takes no option interval"),
        (
            {"strategy": "alternating", "strategy_options": {"interval": 0}},
            "strategy_options",
            ">= 1",
        ),
        ({"advisor": "agent"}, "advisor_checkpoint", "needs a checkpoint"),
        ({"motion": "slow"}, "motion", "unknown motion"),
        ({"sort_rule": "size"}, "sort_rule", "size"),
    ],
)
def test_validate_names_the_field_to_change(
    changes: dict[str, object], field: str, message: str
) -> None:
    spec = RunSpec(config=SMALL, **{"advisor": "oracle", **changes})  # type: ignore[arg-type]
    with pytest.raises(RunSpecError, match=message) as raised:
        spec.validate()
    assert raised.value.field == field


def test_build_gives_the_trainer_the_strategys_options() -> None:
    spec = RunSpec(
        config=SMALL, advisor="oracle", strategy="alternating", strategy_options={"interval": 3}
    )
    trainer, env = spec.build()
    try:
        assert trainer.strategy is not None and trainer.strategy.options() == {"interval": 3}
        assert trainer.strategy.budget == 10
    finally:
        env.close()


def test_settings_read_back_and_old_checkpoint_metadata_still_reads() -> None:
    spec = RunSpec(config=SMALL, advisor="random", strategy="alternating").validate()
    assert RunSpec.from_settings(spec.settings(), SMALL).validate() == spec.replace(budget=10)
    old = {  # what ideeprl train stored before RunSpec
        "advisor": "random", "advisor_checkpoint": None, "error_rate": 0.0,
        "strategy": "alternating", "budget": 10, "interval": 4, "threshold": 0.1,
        "motion": "fast", "sort_rule": "color", "seed": 0, "preset": "paper",
    }  # fmt: skip
    back = RunSpec.from_settings(old, SMALL).validate()
    assert back.strategy_options == {"interval": 4} and back.scenario.reward_scheme == "paper"
