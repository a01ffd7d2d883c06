"""Where the server meets the scenario and the learner, through their documented contracts
(docs/architecture.md): configs, sorting rules, environments, advisors, strategies."""

from __future__ import annotations

from typing import Any

from server.services.errors import Invalid

SB3_DQN = "sb3-dqn"


def build_config(preset: str, overrides: dict[str, Any], **fields: int | None) -> dict[str, Any]:
    """The full learner config as a dict: preset, then `overrides`, then the session's own
    fields (`episodes`, `max_episode_steps`, `advice_budget`) where set; errors name the
    field."""
    from learner import DQNConfig

    try:
        base = DQNConfig.preset(preset)
    except (ValueError, KeyError) as error:
        raise Invalid("preset", str(error).strip("'\"")) from None
    defaults = base.to_dict()
    for name, value in overrides.items():
        default = defaults.get(name)
        number = isinstance(default, int | float) and not isinstance(default, bool)
        if number and isinstance(value, bool):
            raise Invalid("config", f"config.{name} is a number, not {str(value).lower()}")
    data = {**defaults, **overrides}
    data.update({name: value for name, value in fields.items() if value is not None})
    try:
        return DQNConfig.from_dict(data).to_dict()
    except (ValueError, TypeError) as error:
        raise Invalid("config", str(error)) from None


def session_config(
    method: str, preset: str, overrides: dict[str, Any], **fields: int | None
) -> dict[str, Any]:
    """What a session of `method` stores as its config: the learner config
    (`build_config`); for `sb3-dqn` also the Stable-Baselines3 DQN hyperparameters mapped
    from it (`sb3_*` fields, `learner.sb3_dqn`), so an audit and an export show them."""
    config = build_config(preset, overrides, **fields)
    if method != SB3_DQN:
        return config
    from learner import DQNConfig
    from learner.sb3_dqn import sb3_hyperparameters

    try:
        return {**config, **sb3_hyperparameters(DQNConfig.from_dict(config))}
    except ValueError as error:
        raise Invalid("config", str(error)) from None


def require_sb3(method: str) -> None:
    """`sb3-dqn` sessions need the optional Stable-Baselines3; say how to install it."""
    from learner.sb3_dqn import MISSING, available

    if method == SB3_DQN and not available():
        raise Invalid("method", MISSING)


def parse_sort_rule(spec: str | dict[str, str]) -> Any:
    import sim

    try:
        return sim.SortRule.parse(spec).to_spec()
    except (ValueError, TypeError, KeyError) as error:
        raise Invalid("sort_rule", str(error)) from None


def parse_scenario(values: dict[str, Any] | None) -> dict[str, Any]:
    """The scenario options, every one spelled out (defaults filled in), as JSON."""
    import sim

    try:
        return sim.ScenarioOptions.from_dict(values).to_dict()
    except (ValueError, TypeError) as error:
        raise Invalid("scenario", str(error)) from None


def make_env(session: Any, record_motion: bool) -> Any:
    import sim

    return sim.SortingEnv(
        motion=session.motion,
        sort_rule=session.sort_rule,
        max_episode_steps=session.max_episode_steps,
        record_motion=record_motion,
        **parse_scenario(session.scenario),
    )


def make_machine_advisor(session: Any, env: Any) -> Any:
    """The advisor of an `agent`, `oracle` or `random` session."""
    from learner import make_advisor

    if session.method == "agent":
        return make_advisor("agent", checkpoint=session.advisor_checkpoint)
    if session.method == "oracle":
        return make_advisor(
            "oracle",
            sort_rule=session.sort_rule,
            error_rate=session.oracle_error_rate or 0.0,
            seed=session.seed,
        )
    assert session.method == "random", session.method
    return make_advisor("random", seed=session.seed)


def make_strategy(session: Any) -> Any:
    from learner import make_strategy

    if session.strategy is None:
        return None
    return make_strategy(session.strategy, session.advice_budget)


def make_trainer(
    env: Any,
    session: Any,
    advisor: Any,
    strategy: Any,
    callbacks: list[Any],
    torch_threads: int | None,
) -> Any:
    from learner import DQNConfig, Trainer
    from learner.sb3_dqn import split_config

    stored, sb3 = split_config(session.config)
    config = DQNConfig.from_dict(stored)
    if torch_threads:  # a runtime field: a checkpoint resumes under any thread count
        config = config.replace(torch_threads=torch_threads)
    if session.method == SB3_DQN:
        from learner.sb3_dqn import SB3DQNTrainer

        return SB3DQNTrainer(env, config, session.seed, callbacks, hyperparameters=sb3)
    return Trainer(env, config, advisor, strategy, seed=session.seed, callbacks=callbacks)
