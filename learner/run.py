"""One run, described once: what `ideeprl train`, a server session, a batch run and the
REST session body all mean by "train this learner".

Every entry point turns its own input (command-line flags, a stored session row, a batch
plan, a JSON body) into a `RunSpec`, calls `validate()` once, and `build()` gives the
environment and the trainer. An option added here reaches every entry point; the REST
schema is checked against these fields by a test (tests/server/test_run_spec.py).

Torch is not imported by this module: `build()` imports the trainer when it is called.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from learner.advisors import ADVISOR_KINDS, Advisor, make_advisor
from learner.config import DQNConfig
from learner.strategies import (
    _STRATEGIES,
    STRATEGY_NAMES,
    AdvisingStrategy,
    early_budget_problem,
    make_strategy,
)
from sim.rules import SortRule
from sim.scenario import ScenarioOptions

if TYPE_CHECKING:
    import gymnasium as gym

    from learner.sb3_dqn import SB3DQNTrainer
    from learner.trainer import Trainer

ADVISORS = ("none", *ADVISOR_KINDS, "human")
LEARNERS = ("dqn", "sb3-dqn")
"""The paper's learner (`learner.trainer`), or Stable-Baselines3's DQN (`learner.sb3_dqn`,
an independent baseline; the optional `sb3` extra)."""
"""Who advises: nobody (the autonomous DeepRL), a machine advisor the learner builds, or a
person (`human`: the caller supplies the advisor to `build`, the server's `HumanAdvisor`)."""
MOTIONS = ("fast", "physics")
"""`sim.SortingEnv`'s motion modes."""


def strategy_defaults(strategy: str) -> dict[str, Any]:
    """The options a strategy takes besides its budget, with their defaults (read from its
    constructor, so a new option shows up everywhere by itself)."""
    if strategy not in _STRATEGIES:
        raise RunSpecError(
            "strategy",
            f"unknown strategy {strategy!r}; valid strategies: {', '.join(STRATEGY_NAMES)}",
        )
    parameters = inspect.signature(_STRATEGIES[strategy].__init__).parameters
    return {
        name: p.default
        for name, p in parameters.items()
        if name not in ("self", "budget") and p.default is not inspect.Parameter.empty
    }


STRATEGY_OPTIONS: dict[str, dict[str, Any]] = {
    name: strategy_defaults(name) for name in STRATEGY_NAMES
}
"""Every strategy's options and their defaults: `{"alternating": {"interval": 2}, ...}`."""


class RunSpecError(ValueError):
    """A run cannot be built as described; `field` names what to change."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class RunSpec:
    """Everything that decides a run's course; two runs with equal specs take the same
    steps (determinism), whatever entry point started them."""

    seed: int = 0
    """Fixes scene, network, memory, exploration and the machine advisors' draws."""
    config: DQNConfig = field(default_factory=DQNConfig)
    """The learner's hyperparameters (a preset with overrides), `advice_budget` included."""
    preset: str = "paper"
    """The preset `config` started from (a name for logs and checkpoints only)."""
    advisor: str = "none"
    """`ADVISORS`: none, agent, oracle, random, or human."""
    advisor_checkpoint: str | None = None
    """The trained learner's checkpoint that advises (`agent` only)."""
    error_rate: float = 0.0
    """Chance that the oracle advises a wrong action (`oracle` only)."""
    strategy: str = "early"
    """When to ask the advisor (`learner.strategies`); unused without an advisor."""
    strategy_options: dict[str, Any] = field(default_factory=dict)
    """The strategy's options besides its budget (`STRATEGY_OPTIONS`: `interval`,
    `threshold`); missing ones take their defaults, `normalized()` spells them out."""
    budget: int | None = None
    """Advice budget; None: `config.advice_budget`."""
    motion: str = "fast"
    """`fast` (poses set directly) or `physics` (simulated motion)."""
    sort_rule: str | dict[str, str] = "color"
    """Anything `sim.SortRule.parse` takes; `normalized()` gives its JSON spec."""
    scenario: ScenarioOptions = field(default_factory=ScenarioOptions)
    """Reward scheme and realism rates."""
    learner: str = "dqn"
    """`LEARNERS`: the paper's learner, or `sb3-dqn` (never advised)."""
    sb3: dict[str, Any] = field(default_factory=dict)
    """`sb3-dqn` only: its `sb3_*` hyperparameters (`learner.sb3_dqn.sb3_hyperparameters`
    of `config` when empty)."""

    @property
    def advised(self) -> bool:
        return self.advisor != "none"

    @property
    def advice_budget(self) -> int:
        """The advice this run may get: 0 without an advisor."""
        if not self.advised:
            return 0
        return self.config.advice_budget if self.budget is None else self.budget

    def replace(self, **changes: Any) -> RunSpec:
        return dataclasses.replace(self, **changes)

    def normalized(self) -> RunSpec:
        """The same run with every choice spelled out: the sort rule as its spec, the
        strategy's options with their defaults (none without an advisor). Raises
        `RunSpecError` for an unknown name or option."""
        if self.advisor not in ADVISORS:
            raise RunSpecError(
                "advisor", f"unknown advisor {self.advisor!r}; valid: {', '.join(ADVISORS)}"
            )
        if self.learner not in LEARNERS:
            raise RunSpecError(
                "learner", f"unknown learner {self.learner!r}; valid: {', '.join(LEARNERS)}"
            )
        if self.learner == "sb3-dqn" and self.advisor != "none":
            raise RunSpecError("advisor", "Stable-Baselines3's DQN takes no advice")
        if self.motion not in MOTIONS:
            raise RunSpecError(
                "motion", f"unknown motion {self.motion!r}; valid: {', '.join(MOTIONS)}"
            )
        try:
            rule = SortRule.parse(self.sort_rule).to_spec()
        except (ValueError, TypeError, KeyError) as error:
            raise RunSpecError("sort_rule", str(error)) from None
        defaults = strategy_defaults(self.strategy)
        unknown = sorted(set(self.strategy_options) - set(defaults))
        if unknown:
            valid = ", ".join(defaults) or "none"
            raise RunSpecError(
                "strategy_options",
                f"the {self.strategy} strategy takes no option {', '.join(unknown)} "
                f"(its options: {valid})",
            )
        options = {**defaults, **self.strategy_options} if self.advised else {}
        sb3 = dict(self.sb3) if self.learner == "sb3-dqn" else {}
        if self.learner == "sb3-dqn" and not sb3:
            from learner.sb3_dqn import sb3_hyperparameters

            try:
                sb3 = sb3_hyperparameters(self.config)
            except ValueError as error:
                raise RunSpecError("config", str(error)) from None
        return self.replace(sort_rule=rule, strategy_options=options, sb3=sb3)

    def validate(self) -> RunSpec:
        """Every rule a run must satisfy, checked before anything is built; returns the
        normalized spec. Raises `RunSpecError` (a `ValueError`) naming the field."""
        spec = self.normalized()
        if not spec.advised:
            if spec.advisor_checkpoint:
                raise RunSpecError("advisor_checkpoint", "only an agent advisor takes a checkpoint")
            return spec
        if spec.advisor == "agent" and not spec.advisor_checkpoint:
            raise RunSpecError(
                "advisor_checkpoint",
                "an agent advisor needs a checkpoint: the path of a trained learner checkpoint",
            )
        if spec.advisor != "agent" and spec.advisor_checkpoint:
            raise RunSpecError("advisor_checkpoint", "only an agent advisor takes a checkpoint")
        if _STRATEGIES[spec.strategy].needs_values and spec.advisor != "agent":
            raise RunSpecError(
                "strategy",
                f"the {spec.strategy} strategy weighs the advisor's Q-values, which only an "
                "'agent' advisor has; use early or alternating advising",
            )
        if spec.strategy == "early":
            problem = early_budget_problem(spec.advice_budget, spec.config.pretraining_steps)
            if problem:
                raise RunSpecError("advice_budget", problem)
        try:
            spec.make_strategy()
        except ValueError as error:
            raise RunSpecError("strategy_options", str(error)) from None
        return spec

    def make_env(self, record_motion: bool = False) -> gym.Env[Any, Any]:
        import sim

        return sim.SortingEnv(
            motion=self.motion,
            sort_rule=self.sort_rule,
            max_episode_steps=self.config.max_episode_steps,
            record_motion=record_motion,
            **self.scenario.to_dict(),
        )

    def make_advisor(self) -> Advisor | None:
        """The machine advisor (None for none and human: a person is the caller's)."""
        if self.advisor == "agent":
            return make_advisor("agent", checkpoint=self.advisor_checkpoint)
        if self.advisor == "oracle":
            return make_advisor(
                "oracle", sort_rule=self.sort_rule, error_rate=self.error_rate, seed=self.seed
            )
        if self.advisor == "random":
            return make_advisor("random", seed=self.seed)
        return None

    def make_strategy(self) -> AdvisingStrategy | None:
        if not self.advised:
            return None
        return make_strategy(self.strategy, self.advice_budget, **self.strategy_options)

    def build(
        self,
        callbacks: Sequence[Any] = (),
        *,
        record_motion: bool = False,
        wrap_env: Callable[[Any], Any] | None = None,
        wrap_advisor: Callable[[Advisor | None], Advisor | None] | None = None,
    ) -> tuple[Trainer | SB3DQNTrainer, Any]:
        """The trainer and its environment. `wrap_env` wraps the environment before the
        trainer sees it (the server's scene broadcast), `wrap_advisor` the machine advisor
        (the server records its advice; for `human` it gets None and supplies the person)."""
        from learner.trainer import Trainer

        spec = self.validate()
        env = spec.make_env(record_motion)
        if wrap_env is not None:
            env = wrap_env(env)
        if spec.learner == "sb3-dqn":
            from learner.sb3_dqn import SB3DQNTrainer

            return SB3DQNTrainer(
                env, spec.config, spec.seed, list(callbacks), hyperparameters=spec.sb3
            ), env
        advisor = spec.make_advisor()
        if wrap_advisor is not None:
            advisor = wrap_advisor(advisor)
        trainer = Trainer(
            env, spec.config, advisor, spec.make_strategy(), spec.seed, list(callbacks)
        )
        return trainer, env

    def settings(self) -> dict[str, Any]:
        """Plain JSON (a checkpoint's metadata); `from_settings` reads it back."""
        spec = self.normalized()
        return {
            "advisor": spec.advisor,
            "advisor_checkpoint": spec.advisor_checkpoint,
            "error_rate": spec.error_rate,
            "strategy": spec.strategy,
            "strategy_options": dict(spec.strategy_options),
            "budget": spec.advice_budget,
            "motion": spec.motion,
            "sort_rule": spec.sort_rule,
            "seed": spec.seed,
            "preset": spec.preset,
            "scenario": spec.scenario.to_dict(),
            "learner": spec.learner,
            "sb3": dict(spec.sb3),
        }

    @classmethod
    def from_settings(cls, settings: dict[str, Any], config: DQNConfig) -> RunSpec:
        """From `settings()`, or an older checkpoint's metadata (which kept `interval` and
        `threshold` beside the strategy, and no scenario before it existed)."""
        strategy = settings.get("strategy", "early")
        options = settings.get("strategy_options")
        if options is None:
            defaults = strategy_defaults(strategy)
            options = {name: settings[name] for name in defaults if name in settings}
        return cls(
            seed=int(settings.get("seed", 0)),
            config=config,
            preset=settings.get("preset", "paper"),
            advisor=settings.get("advisor", "none"),
            advisor_checkpoint=settings.get("advisor_checkpoint"),
            error_rate=float(settings.get("error_rate", 0.0)),
            strategy=strategy,
            strategy_options=options,
            budget=settings.get("budget"),
            motion=settings.get("motion", "fast"),
            sort_rule=settings.get("sort_rule", "color"),
            scenario=ScenarioOptions.from_dict(settings.get("scenario")),
            learner=settings.get("learner", "dqn"),
            sb3=dict(settings.get("sb3") or {}),
        )
