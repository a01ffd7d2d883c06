"""Where the server meets the learner: a session is a `learner.run.RunSpec`, read from the
REST body when it is created, stored in the session row's columns, and read back by the
worker that runs it and by the batch that looks for it (docs/architecture.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from learner.config import DQNConfig
from learner.run import RunSpec, RunSpecError
from learner.sb3_dqn import split_config
from server.db.models import UNADVISED_METHODS, Method, StudySession
from server.schemas.sessions import SessionCreate
from server.services.errors import Invalid
from sim.rules import SortRule
from sim.scenario import ScenarioOptions

SB3_DQN = "sb3-dqn"


def advisor_of(method: str) -> str:
    """The run's advisor for a session's method (the autonomous DeepRL and the SB3
    baseline have none)."""
    return "none" if method in UNADVISED_METHODS else str(method)


def learner_of(method: str) -> str:
    """The run's learner for a session's method (`learner.run.LEARNERS`)."""
    return SB3_DQN if method == SB3_DQN else "dqn"


def default_motion(method: str) -> str:
    """A person watches a human session move; machines need no motion."""
    return "physics" if method == Method.human else "fast"


def build_config(preset: str, overrides: dict[str, Any], **fields: int | None) -> DQNConfig:
    """The learner config: preset, then `overrides`, then the session's own fields
    (`episodes`, `max_episode_steps`, `advice_budget`) where set; errors name the field."""
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
        return DQNConfig.from_dict(data)
    except (ValueError, TypeError) as error:
        raise Invalid("config", str(error)) from None


def require_sb3(method: str) -> None:
    """`sb3-dqn` sessions need the optional Stable-Baselines3; say how to install it."""
    from learner.sb3_dqn import MISSING, available

    if method == SB3_DQN and not available():
        raise Invalid("method", MISSING)


def parse_sort_rule(spec: str | dict[str, str]) -> str | dict[str, str]:
    try:
        return SortRule.parse(spec).to_spec()
    except (ValueError, TypeError, KeyError) as error:
        raise Invalid("sort_rule", str(error)) from None


def parse_scenario(values: dict[str, Any] | None) -> ScenarioOptions:
    try:
        return ScenarioOptions.from_dict(values)
    except (ValueError, TypeError) as error:
        raise Invalid("scenario", str(error)) from None


def validated(spec: RunSpec) -> RunSpec:
    """`spec.validate()`, its errors as the API's (naming the body's field)."""
    try:
        return spec.validate()
    except RunSpecError as error:
        raise Invalid(error.field, str(error)) from None


def spec_from_body(body: SessionCreate, advisor_checkpoint: str | None = None) -> RunSpec:
    """The run a REST session body describes, checked (`Invalid` names the field).
    `advisor_checkpoint`: the checkpoint file the body's `advisor_checkpoint` resolves to."""
    require_sb3(str(body.method))
    advised = body.method not in UNADVISED_METHODS
    config = build_config(
        body.preset,
        body.config,
        episodes=body.episodes,
        max_episode_steps=body.max_episode_steps,
        advice_budget=body.advice_budget if advised else 0,
    )
    return validated(
        RunSpec(
            seed=body.seed,
            config=config,
            preset=body.preset,
            advisor=advisor_of(body.method),
            advisor_checkpoint=advisor_checkpoint,
            error_rate=body.oracle_error_rate if body.method == Method.oracle else 0.0,
            strategy=body.strategy,
            strategy_options=body.strategy_options.given(),
            motion=body.motion or default_motion(body.method),
            sort_rule=parse_sort_rule(body.sort_rule),
            scenario=parse_scenario(body.scenario.model_dump()),
            learner=learner_of(body.method),
        )
    )


def stored(spec: RunSpec) -> dict[str, Any]:
    """The session row's columns that hold the run (`spec_of` reads them back)."""
    oracle = spec.advisor == "oracle"
    return {
        "seed": spec.seed,
        "config": {**spec.config.to_dict(), **spec.sb3},  # sb3-dqn's mapped settings too
        "sort_rule": spec.sort_rule,
        "strategy": spec.strategy if spec.advised else None,
        "strategy_options": dict(spec.strategy_options) if spec.advised else None,
        "advice_budget": spec.advice_budget,
        "advisor_checkpoint": spec.advisor_checkpoint,
        "oracle_error_rate": spec.error_rate if oracle else None,
        "motion": spec.motion,
        "scenario": spec.scenario.to_dict(),
        "episodes": spec.config.episodes,
        "max_episode_steps": spec.config.max_episode_steps,
    }


def spec_of(session: StudySession, torch_threads: int | None = None) -> RunSpec:
    """The run a stored session describes, as the learner reads it back: config fields
    added since it was stored take their defaults, as do a strategy's options stored before
    they could be set. `torch_threads` is a runtime field (a checkpoint resumes under any)."""
    stored_config, sb3 = split_config(session.config)
    config = DQNConfig.from_dict(stored_config)
    if torch_threads:
        config = config.replace(torch_threads=torch_threads)
    return RunSpec(
        seed=session.seed,
        config=config,
        advisor=advisor_of(session.method),
        advisor_checkpoint=session.advisor_checkpoint,
        error_rate=session.oracle_error_rate or 0.0,
        strategy=session.strategy or "early",
        strategy_options=session.strategy_options or {},
        budget=session.advice_budget,
        motion=session.motion,
        sort_rule=session.sort_rule,
        scenario=ScenarioOptions.from_dict(session.scenario),
        learner=learner_of(session.method),
        sb3=sb3,
    ).normalized()


def identity(method: str, spec: RunSpec) -> dict[str, Any]:
    """What identifies a run among a study's sessions (the batch finds its runs by it):
    the method and every stored choice that decides the run's course, in the JSON form the
    database gives back; the label is a name, not part of it."""
    columns = stored(spec)
    path = columns["advisor_checkpoint"]
    return json.loads(
        json.dumps(
            {
                "method": str(method),
                "seed": columns["seed"],
                "config": columns["config"],
                "sort_rule": columns["sort_rule"],
                "strategy": columns["strategy"],
                "strategy_options": columns["strategy_options"],
                "advisor_checkpoint": None if path is None else str(Path(path).resolve()),
                "oracle_error_rate": columns["oracle_error_rate"],
                "motion": columns["motion"],
                "scenario": columns["scenario"],
            }
        )
    )


def session_identity(session: StudySession) -> dict[str, Any] | None:
    """`identity` of a stored session; None when the learner or the scenario can no longer
    read it (a field since removed): then it is never the same run as a new one."""
    try:
        return identity(session.method, spec_of(session))
    except (ValueError, TypeError):
        return None
