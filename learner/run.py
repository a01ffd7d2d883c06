"""One run, described once: what `ideeprl train`, a server session, a batch run, a replay
and the REST body all mean by "train this learner".

`RunSpec` is a tree of frozen dataclasses (the run, its learner `config`, its
`strategy_options`, its `scenario`); every field has its docstring under it and its range
beside it (`learner.fields`). Everything that shows or takes a run is derived from it: the
flags of `ideeprl train` and `ideeprl batch`, the REST body and its OpenAPI schema, the
stored JSON document, the export's columns and their dictionary, and the report's settings
audit. An option added here reaches all of them.

- `RunSpec.from_json(data)`: a run from JSON (the REST body's `run`, a stored session, an
  export's `run_spec` column), every value checked; fields left out take their defaults, the
  learner config's the preset's.
- `validate()`: the rules between fields, checked before anything is stored or started.
- `pinned()`: the numerics (device, precision, compiled convolutions and their layers,
  threads) resolved on this machine; a session stores its run pinned, and
  `numerics_problem()` says why another machine cannot honour it.
- `build()`: the environment and the trainer.

Torch is not imported by this module: `build()` imports the trainer when it is called.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, cast

from learner import machine
from learner.advisors import ADVISOR_KINDS, Advisor, make_advisor
from learner.config import PRESET_FIELDS, DQNConfig, Preset
from learner.evaluators import AdvisorEvaluator, AnyEvaluator
from learner.fields import (
    FieldError,
    bounded,
    build,
    checked,
    flatten,
    group,
    leaves,
    nest,
    to_json,
)
from learner.fitted_ratings import FittedEvaluator, read_evaluator_model
from learner.sb3_spec import sb3_hyperparameters
from learner.strategies import (
    _STRATEGIES,
    STRATEGY_NAMES,
    AdvisingStrategy,
    AnyAdvisor,
    early_budget_problem,
    make_strategy,
)
from sim.rules import SortRule
from sim.scenario import ScenarioOptions
from tasks import OptionValue, Task, TaskError, get_task

TASK_NAME = r"[A-Za-z_][\w.]*(:[A-Za-z_]\w*)?"
"""A built-in task's name, or package.module:callable."""

if TYPE_CHECKING:
    import gymnasium as gym

    from learner.procedure import Schedule
    from learner.sb3_dqn import SB3DQNTrainer
    from learner.trainer import Trainer

SPEC_VERSION = 1
"""Version of the stored run document (`RunSpec.to_json`); `from_json` reads this and older."""
METHODS = (
    "autonomous", "agent", "human", "oracle", "random", "procedure", "sb3-dqn", "fitted",
    "replayed",
)  # fmt: skip
"""A run's method: who advises it (nobody, a trained agent, a person, the oracle, a random
advisor, an advisor fitted to a study's people), `procedure` (the procedure control: an
advised run's advising procedure with random actions, `learner.procedure`), `sb3-dqn`,
Stable-Baselines3's DQN unadvised (an independent baseline), or `replayed`: a recorded
session's advice stream fed by order (its session holds the stream,
`sessions.replay_stream`; `ideeprl replay`)."""
Method = Literal[
    "autonomous",
    "agent",
    "human",
    "oracle",
    "random",
    "procedure",
    "sb3-dqn",
    "fitted",
    "replayed",
]
UNADVISED = ("autonomous", "sb3-dqn")
"""Methods without an advisor: no strategy, no advice budget."""
ADVISORS = ("none", *ADVISOR_KINDS, "human", "procedure", "replayed")
"""Who advises: nobody, a machine advisor the learner builds, a person (`human`: the
caller supplies the advisor to `build`, the server's `HumanAdvisor`), the procedure control's
random advice, or a recorded stream (`replayed`: the caller supplies a
`learner.advisors.RecordedAdvisor`)."""
REPLAY_STRATEGIES = ("early", "alternating")
"""Strategies a replayed stream can follow: those that ask without weighing the advisor's
own values (a stream has none)."""
LEARNERS = ("dqn", "sb3-dqn")
"""The paper's learner (`learner.trainer`), or Stable-Baselines3's DQN (`learner.sb3_dqn`,
an independent baseline; the optional `sb3` extra)."""
MOTIONS = ("fast", "physics")
"""`sim.SortingEnv`'s motion modes."""
Motion = Literal["fast", "physics"]
Strategy = Literal[STRATEGY_NAMES]  # type: ignore[valid-type]
FEEDBACK_KINDS = ("advice", "evaluative")
"""The paper's two strategies of interactive feedback (its section 2): corrective advice
(policy shaping: the advisor names the action taken) or evaluative feedback (reward
shaping: the advisor judges the learner's own action, `learner.evaluators`)."""
Feedback = Literal["advice", "evaluative"]
FEEDBACK_METHODS = ("shaping", "rating_model")
"""How the learner uses evaluative feedback (`learner.trainer`, `learner.rating_model`):
shaping the judged step's remembered reward only (Ng et al. 1999; TAMER+RL's reward
shaping), or also training a model of the rating that shapes the steps not judged (TAMER+RL,
Knox and Stone 2010; Deep TAMER, Warnell et al. 2018)."""
FeedbackMethod = Literal["shaping", "rating_model"]
EVALUATORS = ("agent", "oracle", "fitted", "human", "replayed", "procedure")
"""Methods whose advisor can judge an action (evaluative feedback): the machines that name
the right one, an evaluator fitted to people's ratings (`learner.fitted_ratings`), a person
rating on the advice page (`runs.worker.rating`), a recorded
session's ratings fed by order (`replayed`: the caller supplies a
`learner.evaluators.RecordedEvaluator`), and the procedure control of a judged run
(uninformed judgements at its judged steps)."""
MAX_SEED = 2**31 - 1
FRAME_BYTES = 64 * 64 * 3
"""One stored observation (uint8)."""
PROCESS_BYTES = 600 * 2**20
"""A run's process besides its replay memory: torch, the simulator, the network."""


def strategy_defaults(strategy: str) -> dict[str, Any]:
    """The options a strategy takes besides its budget, with their defaults (read from its
    constructor, so a new option shows up everywhere by itself)."""
    if strategy not in _STRATEGIES:
        raise RunSpecError(
            "strategy",
            f"unknown strategy; valid strategies: {', '.join(STRATEGY_NAMES)}",
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


class RunSpecError(FieldError):
    """A run cannot be built as described; `field` names what to change."""


@dataclass(frozen=True)
@checked()
class StrategyOptions:
    """The advising strategy's options besides its budget; None: the strategy's default
    (`STRATEGY_OPTIONS`), or the strategy takes no such option."""

    interval: int | None = bounded(None, 1, 100_000, role="treatment")
    """alternating: advise on every Nth training step (its default 2) [steps]."""
    threshold: float | None = bounded(None, 0.0, 1_000_000.0, role="treatment")
    """importance, mistake_correcting: the advisor's Q-value spread (max - min) from which a
    state is important (their default 0.1)."""

    def given(self) -> dict[str, Any]:
        """The options set, by name."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


_OPTION_NAMES = {f.name for f in dataclasses.fields(StrategyOptions)}
assert all(set(options) <= _OPTION_NAMES for options in STRATEGY_OPTIONS.values()), (
    "a strategy takes an option StrategyOptions does not declare"
)


@dataclass(frozen=True)
@checked()
class RunSpec:
    """Everything that decides a run's course; two runs with equal specs on the same CPU kind
    take the same steps (determinism), whatever entry point started them."""

    method: Method = bounded("autonomous", role="treatment")
    """Who advises: autonomous (nobody: the paper's DeepRL), agent (a trained learner's
    checkpoint), human (a person in the browser), oracle (the correct action, with an error
    rate), random, fitted (advises like a study's people: `fitted_model`); sb3-dqn,
    Stable-Baselines3's DQN unadvised (needs the sb3 extra); or replayed, a recorded
    session's advice (or, under evaluative feedback, its ratings) fed by order (made by
    ideeprl replay)."""
    seed: int = bounded(0, 0, MAX_SEED, role="seed")
    """Fixes scene, network, memory, exploration and the machine advisors' draws."""
    preset: Preset = bounded("paper")
    """The learner preset the config starts from: paper, modern or authors (what the
    authors' Keras code did); fields given in `config` override it. Left out of a run's
    document: its task's (`Task.preset`)."""
    config: DQNConfig = group(DQNConfig, prefix="config_")
    """The learner's hyperparameters (the preset's, with the fields given here)."""
    strategy: Strategy = bounded("early", role="treatment")
    """When to ask the advisor (`learner.strategies`): early (the paper's: the last
    advice_budget pretraining steps), alternating, importance, mistake_correcting; unused
    without an advisor."""
    strategy_options: StrategyOptions = group(StrategyOptions, prefix="strategy_")
    """The strategy's options besides its budget."""
    feedback: Feedback = bounded("advice", role="treatment")
    """The kind of feedback the advisor gives (the paper's section 2): advice (policy
    shaping, the paper's: the advised action is taken) or evaluative (reward shaping: the
    learner takes its own action and the advisor judges it, good +1 or bad -1, on the
    steps the strategy and the advice budget give it); evaluative takes method oracle,
    agent, fitted (a model fitted to ratings) or human, strategy early, alternating or
    importance."""
    feedback_weight: float = bounded(1.0, 0.0, 100.0, role="treatment")
    """Evaluative feedback: w in the reward the learner remembers for a judged step, the
    environment's plus w times the judgement (TAMER+RL's reward shaping). 1: a judgement
    weighs as much as the task's largest rewards (a placement's +1, a misplacement's -1),
    so that it counts where the environment rewards nothing (a grab, a move)."""
    feedback_method: FeedbackMethod = bounded("shaping", role="treatment")
    """Evaluative feedback: how the learner uses a judgement. shaping: the judged step's
    remembered reward only (environment's + w * judgement); rating_model: that, and the
    judgements so far train a model H(s, a) of the rating (linear in pooled features of the
    observation), and every step not judged after one remembers the environment's reward +
    w * H (TAMER+RL, Deep TAMER), so a judgement counts beyond its step. shaping by default:
    the paper's section 2 names reward shaping, and it adds no model of its own."""
    rating_model_steps: int | None = bounded(None, 1, 100_000_000, role="treatment")
    """feedback_method rating_model: how many steps after the latest judgement the model
    shapes; none: to the end of the run [steps]."""
    rating_time_out_s: float = bounded(10.0, 1.0, 600.0, role="treatment")
    """Evaluative feedback from a person: how long the learner waits for a rating of its
    action (good or bad) before it goes on with none (recorded as no answer)."""
    advisor_checkpoint: str | None = bounded(None, role="treatment", max_length=1000)
    """The trained learner whose checkpoint advises (method agent): `session:ID` (a session
    of this installation), or a checkpoint file's path."""
    schedule: str | None = bounded(None, role="treatment", max_length=1000)
    """The advised run whose advising procedure this control follows (method procedure): a
    schedule file (`learner.procedure.Schedule`; the batch writes one per paired run)."""
    error_rate: float = bounded(0.0, 0.0, 1.0, role="treatment", column="oracle_error_rate")
    """Chance that the oracle advises a wrong action (method oracle) [probability]."""
    decision_time_median_s: float | None = bounded(
        None,
        0.0,
        3600.0,
        role="treatment",
        exclusive_minimum=True,
        column="oracle_decision_time_median_s",
    )
    """The oracle's simulated decision times (method oracle): their median, log-normal;
    logged as each advice's decision_time_s, never waited. None: no times [s]."""
    decision_time_sigma: float = bounded(
        0.5, 0.0, 5.0, role="treatment", column="oracle_decision_time_sigma"
    )
    """The spread of the oracle's simulated decision times: the standard deviation of
    their logarithm (method oracle, with decision_time_median_s)."""
    fitted_model: str | None = bounded(None, role="treatment", max_length=1000)
    """The fitted advisor's model (method fitted): `fitted:ID` through the API (a model
    `ideeprl fit` stored), or the path of its JSON file; under evaluative feedback, a model
    fitted to ratings (a fitted evaluator)."""
    motion: Motion | None = bounded(None)
    """fast (poses set directly) or physics (simulated motion); none: physics for a human
    session (a person watches it move), fast otherwise."""
    sort_rule: str | dict[str, str] = bounded("color", max_length=400)
    """The sorting rule: color (blue right, red left), shape (cubes left, the rest right),
    or a map of all six objects to a side, as JSON or as cube/red=left;cube/blue=right;..."""
    scenario: ScenarioOptions = group(ScenarioOptions)
    """Reward scheme and realism rates (`sim.ScenarioOptions`)."""
    task: str = bounded("sorting", max_length=200, pattern=TASK_NAME)
    """What the agent learns to do (`tasks`): sorting (the paper's robot; its options are
    motion, sort_rule and scenario), gridworld (MiniGrid's empty room), or a researcher's
    own as package.module:callable, a function marked @tasks.task_factory."""
    task_options: dict[str, OptionValue] = bounded({}, max_length=2000)
    """The task's own options, a JSON object (gridworld: size, max_steps); the sorting
    task takes none here."""

    # --- what the run is ---------------------------------------------------------------
    @property
    def advisor(self) -> str:
        """`ADVISORS`: none for the unadvised methods, else the method."""
        return "none" if self.method in UNADVISED else self.method

    @property
    def learner(self) -> str:
        """`LEARNERS`: Stable-Baselines3's for sb3-dqn, else the paper's."""
        return "sb3-dqn" if self.method == "sb3-dqn" else "dqn"

    @property
    def advised(self) -> bool:
        return self.advisor != "none"

    @property
    def advice_budget(self) -> int:
        """The advice this run may get: 0 without an advisor."""
        return self.config.advice_budget if self.advised else 0

    @property
    def sb3(self) -> dict[str, Any]:
        """sb3-dqn only: SB3's hyperparameters, mapped from the config."""
        if self.learner != "sb3-dqn":
            return {}
        return sb3_hyperparameters(self.config)

    def replace(self, **changes: Any) -> RunSpec:
        return dataclasses.replace(self, **changes)

    # --- JSON ------------------------------------------------------------------------------
    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RunSpec:
        """A run from JSON: every value checked (`FieldError` names the field and its range),
        unknown names refused; fields left out take their defaults, and the config's the
        preset's. Reads documents of `SPEC_VERSION` and older (`version` may be absent)."""
        if not isinstance(data, Mapping):
            raise RunSpecError("run", "a run must be a JSON object")
        data = dict(data)
        version = data.pop("version", SPEC_VERSION)
        if version not in range(1, SPEC_VERSION + 1):
            raise RunSpecError(
                "version", f"run documents of version 1 to {SPEC_VERSION} can be read"
            )
        if "preset" not in data:
            data["preset"] = _task_preset(data.get("task", "sorting"))
        preset = data["preset"]
        config = data.get("config", {})
        if isinstance(preset, str) and preset in PRESET_FIELDS and isinstance(config, Mapping):
            data["config"] = {**PRESET_FIELDS[preset], **config}  # else `build` names the field
        return build(cls, data)

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> tuple[RunSpec, int]:
        """The run a checkpoint of `Trainer.save_checkpoint` continues, read from its
        metadata (an older checkpoint's through `from_old_settings`), and the global step it
        stands at. `ValueError` for a file that is no such checkpoint."""
        from learner.checkpoint import read_checkpoint  # torch: only when resuming

        state = read_checkpoint(path)
        settings = dict(state["metadata"])
        if "advisor" not in settings and "method" not in settings:
            raise ValueError(f"{path} was not written by ideeprl train")
        config = DQNConfig.from_dict(state["config"])
        if "version" in settings:
            return cls.from_json(settings), int(state["global_step"])
        return from_old_settings(settings, config), int(state["global_step"])

    def to_json(self) -> dict[str, Any]:
        """The stored document: every field spelled out, with its `version`."""
        return {"version": SPEC_VERSION, **to_json(self)}

    def with_values(self, values: Mapping[str, Any]) -> RunSpec:
        """This run with some fields changed, named by leaf (`batch_size`, `reward_scheme`,
        `interval`), each checked; a new `preset` is refused (it would change config fields
        this run set: describe such a run from scratch)."""
        if "preset" in values and values["preset"] != self.preset:
            raise RunSpecError(
                "preset", "a preset cannot be changed on a described run; give it with the run"
            )
        merged = to_json(self)
        for name, value in nest(values, type(self)).items():
            if (
                isinstance(value, dict)
                and isinstance(merged.get(name), dict)
                and name != "sort_rule"
            ):
                merged[name] = {**merged[name], **value}
            else:
                merged[name] = value
        return type(self).from_json(merged)

    def values(self) -> dict[str, Any]:
        """Every leaf's value by leaf name (`with_values`' names)."""
        return flatten(to_json(self), type(self))

    def identity(self) -> dict[str, Any]:
        """What identifies this run among a study's sessions (a batch finds its runs by it):
        every field of the normalized run in its stored JSON form, the advisor's checkpoint
        and the fitted model as absolute paths, and numerics only where they were asked for
        (not left `auto`): a run's pinned numerics are checked when it resumes
        (`numerics_problem`)."""
        doc = self.normalized().to_json()
        doc.pop("version")
        checkpoint = doc["advisor_checkpoint"]
        if checkpoint is not None and not checkpoint.startswith("session:"):
            doc["advisor_checkpoint"] = str(Path(checkpoint).resolve())
        if doc.get("fitted_model") and not doc["fitted_model"].startswith("fitted:"):
            doc["fitted_model"] = str(Path(doc["fitted_model"]).resolve())
        for name in NUMERICS:
            if doc["config"].get(name) in OPEN_NUMERICS:
                doc["config"].pop(name)
        return json.loads(json.dumps(doc))

    def is_run(self, wanted: Mapping[str, Any]) -> bool:
        """Whether this (stored) run is the run `wanted` (an `identity`): equal in
        everything, numerics wanted `auto` matching whatever this run pinned."""
        stored = self.identity()
        for name in NUMERICS:
            if name not in wanted["config"]:
                stored["config"].pop(name, None)
        return stored == wanted

    # --- rules ---------------------------------------------------------------------------
    def normalized(self) -> RunSpec:
        """The same run with every choice spelled out: the motion, the sort rule as its spec,
        the strategy's options with their defaults (none without an advisor, and no advice
        budget). Raises `RunSpecError` for an option the strategy does not take."""
        try:
            rule = SortRule.parse(self.sort_rule).to_spec()
        except (ValueError, TypeError, KeyError):
            raise RunSpecError(
                "sort_rule",
                "sort_rule must be color, shape, or a map of all six objects (cube, cylinder, "
                "disk; red, blue) to left or right",
            ) from None
        defaults = strategy_defaults(self.strategy)
        given = self.strategy_options.given()
        unknown = sorted(set(given) - set(defaults))
        if unknown and self.advised:
            valid = ", ".join(defaults) or "none"
            raise RunSpecError(
                f"strategy_options.{unknown[0]}",
                f"the {self.strategy} strategy takes no option {', '.join(unknown)} "
                f"(its options: {valid})",
            )
        options = StrategyOptions(**({**defaults, **given} if self.advised else {}))
        config = self.config if self.advised else self.config.replace(advice_budget=0)
        motion = self.motion or ("physics" if self.method == "human" else "fast")
        oracle = self.method == "oracle"
        evaluative = self.advised and self.feedback == "evaluative"
        modelled = evaluative and self.feedback_method == "rating_model"
        task_options = self.task_options
        if self.task != "sorting":
            try:
                task_options = self.the_task.checked_options(self.task_options)
            except TaskError as error:
                raise RunSpecError("task_options", str(error)) from None
        return self.replace(
            task_options=task_options,
            sort_rule=rule,
            strategy=self.strategy if self.advised else "early",
            strategy_options=options,
            config=config,
            motion=motion,
            error_rate=self.error_rate if self.method == "oracle" else 0.0,
            decision_time_median_s=self.decision_time_median_s if oracle else None,
            decision_time_sigma=self.decision_time_sigma if oracle else 0.5,
            feedback="evaluative" if evaluative else "advice",
            feedback_weight=self.feedback_weight if evaluative else 1.0,
            feedback_method=self.feedback_method if evaluative else "shaping",
            rating_model_steps=self.rating_model_steps if modelled else None,
            rating_time_out_s=self.rating_time_out_s if evaluative else 10.0,
        )

    @property
    def the_task(self) -> Task:
        """The task the run names (`RunSpecError` when it cannot be had)."""
        try:
            return get_task(self.task)
        except TaskError as error:
            raise RunSpecError("task", str(error)) from None

    def env_options(self) -> dict[str, OptionValue]:
        """The options its task's environment is made with: the sorting task's from the
        run's own sorting fields, another task's from `task_options`."""
        if self.task == "sorting":
            return {
                "motion": self.motion or "fast",
                "sort_rule": self.sort_rule,
                **self.scenario.to_dict(),
            }
        return self.the_task.checked_options(self.task_options)

    def _check_task(self) -> None:
        """The sorting task's fields belong to it; another task's options to that task."""
        if self.task == "sorting":
            if self.task_options:
                raise RunSpecError(
                    "task_options",
                    "the sorting task takes its options from motion, sort_rule and scenario, "
                    "not task_options",
                )
            return
        self.the_task  # noqa: B018 (raises for a task that cannot be had)
        sorting = RunSpec()
        for name in ("sort_rule", "scenario"):
            if getattr(self, name) != getattr(sorting, name):
                raise RunSpecError(
                    name, f"{name} is the sorting task's; task {self.task} does not take it"
                )
        if self.motion not in (None, "fast", "physics"):
            raise RunSpecError("motion", "motion is the sorting task's")

    def _check_conv_kernel(self) -> None:
        """Compiled convolutions (`config.conv_kernel`) only where they compute the run's."""
        config = self.config
        kernel = config.conv_kernel
        if kernel in ("auto", "none"):
            return
        precision = machine.CONV_KERNEL_VARIANTS[machine.conv_kernel_parts(kernel)[0]][1]
        if config.update != "fast" or config.device.startswith("cuda") or self.learner != "dqn":
            raise RunSpecError(
                "config.conv_kernel",
                f"conv_kernel {kernel} computes convolutions of the DQN's fast update on the "
                "CPU; this run computes none (use conv_kernel none)",
            )
        if config.precision not in ("auto", precision):
            raise RunSpecError(
                "config.conv_kernel",
                f"conv_kernel {kernel} computes {precision} convolutions and the run's "
                f"precision is {config.precision}",
            )

    def validate(self) -> RunSpec:
        """Every rule between fields, checked before anything is built or stored; returns the
        normalized spec. Raises `RunSpecError` (a `ValueError`) naming the field."""
        self._check_task()
        spec = self.normalized()
        if spec.learner == "sb3-dqn":
            try:
                sb3_hyperparameters(spec.config)
            except ValueError as error:
                raise RunSpecError("config.epsilon_min", str(error)) from None
        if spec.method != "agent" and spec.advisor_checkpoint:
            raise RunSpecError(
                "advisor_checkpoint", "only method agent takes an advisor_checkpoint"
            )
        if (spec.method == "procedure") != bool(spec.schedule):
            raise RunSpecError(
                "schedule",
                "method procedure needs schedule: the advised run whose procedure it follows"
                if spec.method == "procedure"
                else "only method procedure takes a schedule",
            )
        spec._check_conv_kernel()
        if spec.method != "fitted" and spec.fitted_model:
            raise RunSpecError("fitted_model", "only method fitted takes a fitted_model")
        if spec.method == "fitted" and not spec.fitted_model:
            raise RunSpecError(
                "fitted_model",
                "method fitted needs fitted_model: a model `ideeprl fit` stored (fitted:ID "
                "through the API, or the path of its JSON file)",
            )
        if not spec.advised:
            return spec
        if spec.method == "agent" and not spec.advisor_checkpoint:
            raise RunSpecError(
                "advisor_checkpoint",
                "method agent needs advisor_checkpoint: the trained learner that advises",
            )
        if spec.feedback == "evaluative":
            spec._check_evaluative()
            if self.rating_model_steps is not None and spec.feedback_method != "rating_model":
                raise RunSpecError(
                    "rating_model_steps",
                    "only feedback_method rating_model takes rating_model_steps",
                )
        if spec.method == "replayed" and spec.strategy not in REPLAY_STRATEGIES:
            raise RunSpecError(
                "strategy",
                f"a replayed stream has no Q-values for the {spec.strategy} strategy to weigh; "
                f"replay with {' or '.join(REPLAY_STRATEGIES)} advising",
            )
        if _STRATEGIES[spec.strategy].needs_values and spec.method not in ("agent", "procedure"):
            raise RunSpecError(
                "strategy",
                f"the {spec.strategy} strategy weighs the advisor's Q-values, which only an "
                "agent advisor has; use early or alternating advising",
            )
        if spec.strategy == "early":
            problem = early_budget_problem(spec.advice_budget, spec.config.pretraining_steps)
            if problem:
                raise RunSpecError("config.advice_budget", problem)
        try:
            spec.make_strategy()
        except ValueError as error:
            raise RunSpecError("strategy_options", str(error)) from None
        return spec

    def _check_evaluative(self) -> None:
        if self.method not in EVALUATORS:
            raise RunSpecError(
                "feedback",
                f"evaluative feedback is judged by method {' or '.join(EVALUATORS)}"
                f"; method {self.method} cannot judge",
            )
        if not _STRATEGIES[self.strategy].judges:
            raise RunSpecError(
                "strategy",
                f"the {self.strategy} strategy decides by the advisor's action, which an "
                "evaluator does not give; use early, alternating or importance",
            )

    # --- numerics --------------------------------------------------------------------------
    def pinned(self, threads: int | None = None) -> RunSpec:
        """The run with its numerics decided on this machine, as a session stores it: the
        device (`auto`: cuda when present, else cpu), the convolution precision (`auto`:
        bf16 where the device runs it natively, else fp32), the compiled convolutions
        (`auto`: for the sorting task's fast update on the CPU, the variant and layers
        `machine.conv_kernel_for` gives, else none) and the torch threads (0: half the
        cores, 1 to 4, unless `threads` says how many a run gets here). Also checks
        that the replay memory fits this machine."""
        config = self.config
        device = config.device
        if device == "auto":
            device = "cuda" if machine.cuda_present() else "cpu"
        precision = config.precision
        if precision == "auto":
            native = device.startswith("cuda") or machine.bf16_native_cpu()
            precision = "bf16" if native and config.update == "fast" else "fp32"
        threads = config.torch_threads or threads or machine.default_threads()
        conv_kernel = config.conv_kernel
        if conv_kernel == "auto":
            takes = device == "cpu" and config.update == "fast" and self.task == "sorting"
            conv_kernel = machine.conv_kernel_for(precision) if takes else "none"
        spec = self.replace(
            config=config.replace(
                device=device, precision=precision, torch_threads=threads, conv_kernel=conv_kernel
            )
        )
        spec.check_memory()
        return spec

    def repinned(self) -> RunSpec:
        """The run pinned anew on this machine, as an override of its numerics resumes it:
        its device, precision and compiled convolutions chosen here, its threads kept."""
        config = self.config.replace(device="auto", precision="auto", conv_kernel="auto")
        return self.replace(config=config).pinned(self.config.torch_threads)

    def numerics_problem(self) -> str | None:
        """Why this machine cannot take the steps this pinned run takes, or None."""
        config = self.config
        if config.device.startswith("cuda") and not machine.cuda_present():
            return f"the run was pinned to {config.device}, and this machine has no CUDA device"
        if (
            config.precision == "bf16"
            and config.update == "fast"
            and not config.device.startswith("cuda")
            and not machine.bf16_native_cpu()
        ):
            return (
                "the run was pinned to bfloat16 convolutions, which this CPU "
                f"({machine.cpu_kind()}) does not run natively: its steps would differ. Resume "
                "it on a CPU with AVX-512 BF16 or AMX, or override the numerics (recorded)"
            )
        kernel = config.conv_kernel
        if kernel in ("auto", "none"):
            return None
        variant, layers = machine.conv_kernel_parts(kernel)
        if not machine.conv_kernel_runs(kernel):
            return (
                f"the run was pinned to the {variant} variant of the compiled convolutions "
                f"(conv_kernel {kernel}), which does not run here ({machine.cpu_kind()}: the "
                "CPU lacks its instructions, or `make kernels` has not built it): its steps "
                "would differ. Resume it where that variant runs, or override the numerics "
                "(recorded)"
            )
        if not machine.conv_kernel_layers_computed(kernel):
            computed = " or ".join(
                ", ".join(map(str, sorted(s))) for s in machine.CONV_KERNEL_LAYER_SETS
            )
            return (
                f"the run was pinned to compiled convolutions for layers "
                f"{', '.join(map(str, sorted(layers)))} (conv_kernel {kernel}), and this code "
                f"computes layers {computed} with them: its steps would differ. Resume it "
                "with the code it was pinned with, or override the numerics (recorded)"
            )
        return None

    def memory_needed(self) -> int:
        """Bytes the run's process needs: its replay memory's frames and the rest."""
        return self.config.memory_size * FRAME_BYTES + PROCESS_BYTES

    def check_memory(self, total: int | None = None) -> None:
        """`RunSpecError` when the replay memory cannot fit the machine (`total` bytes)."""
        total = machine.total_memory() if total is None else total
        if total and self.memory_needed() > total:
            raise RunSpecError(
                "config.memory_size",
                f"config.memory_size needs about {self.memory_needed() / 2**30:.1f} GiB for "
                f"its frames and the process; this machine has {total / 2**30:.1f} GiB",
            )

    def make_env(self, record_motion: bool = False) -> gym.Env[Any, Any]:
        """The run's task's environment (its simulator imported now)."""
        return self.the_task.make_env(
            self.env_options(), self.config.max_episode_steps, record_motion
        )

    def make_advisor(self) -> Advisor | None:
        """The machine advisor (None for none, human and replayed: a person, or a recorded
        stream, is the caller's; and under evaluative feedback, whose is `make_evaluator`)."""
        if self.feedback == "evaluative":
            return None
        return self._machine_advisor()

    def make_evaluator(self) -> AnyEvaluator | None:
        """Under evaluative feedback, the machine evaluator: the oracle's correct action or
        the agent's greedy one is good, any other bad, each judgement wrong with the
        oracle's error rate (`learner.evaluators.AdvisorEvaluator`); the procedure
        control's, a random action's (good as often as an evaluator with one right action
        whose learner acts at random, whatever the state: uninformed); method fitted's,
        rating as the people of its model did (`learner.fitted_ratings.FittedEvaluator`);
        else None."""
        if self.feedback == "evaluative" and self.method == "fitted":
            return self._fitted_evaluator()
        if self.feedback != "evaluative" or self.method not in ("agent", "oracle", "procedure"):
            return None  # a person's ratings, or a recorded stream, are the caller's
        advisor = self.replace(error_rate=0.0)._machine_advisor()
        assert advisor is not None, "validate() admits evaluative feedback from evaluators only"
        return AdvisorEvaluator(advisor, self.error_rate, self.seed)

    def _fitted_evaluator(self) -> FittedEvaluator:
        try:
            return FittedEvaluator(
                read_evaluator_model(self.fitted_model or ""),
                seed=self.seed,
                task=self.the_task,
                task_options=self.env_options(),
            )
        except ValueError as error:
            raise RunSpecError("fitted_model", str(error)) from None

    def _machine_advisor(self) -> Advisor | None:
        if self.method == "agent":
            return make_advisor("agent", checkpoint=self.advisor_checkpoint)
        if self.method == "oracle":
            return make_advisor(
                "oracle",
                task=self.the_task,
                task_options=self.env_options(),
                error_rate=self.error_rate,
                seed=self.seed,
                decision_time_median_s=self.decision_time_median_s,
                decision_time_sigma=self.decision_time_sigma,
            )
        if self.method == "fitted":
            try:
                return make_advisor(
                    "fitted",
                    model=self.fitted_model,
                    task=self.the_task,
                    task_options=self.env_options(),
                    seed=self.seed,
                    budget=self.advice_budget,
                )
            except ValueError as error:
                raise RunSpecError("fitted_model", str(error)) from None
        if self.method in ("random", "procedure"):
            return make_advisor("random", seed=self.seed, n_actions=self.the_task.n_actions)
        return None

    def make_strategy(self) -> AdvisingStrategy | None:
        if not self.advised:
            return None
        return make_strategy(self.strategy, self.advice_budget, **self.strategy_options.given())

    def steps_before_first_turn(self) -> int:
        """Random practice steps before the earliest step its feedback may be asked at (a
        run advised by none counts as early advising with no budget): where a person's
        session waits for them, and where a pool's practice on a cluster node ends."""
        strategy = self.make_strategy() or make_strategy("early", 0)
        return strategy.first_advice_step(self.config.pretraining_steps) - 1

    def build(
        self, callbacks: Sequence[Any] = (), *, record_motion: bool = False
    ) -> tuple[Trainer | SB3DQNTrainer, Any]:
        """The trainer and its environment, as the run describes them."""
        spec = self.validate()
        env = spec.make_env(record_motion)
        trainer = spec.make_trainer(env, spec.make_advisor(), callbacks, spec.make_evaluator())
        return trainer, env

    def make_trainer(
        self,
        env: Any,
        advisor: AnyAdvisor | None,
        callbacks: Sequence[Any] = (),
        evaluator: AnyEvaluator | None = None,
    ) -> Trainer | SB3DQNTrainer:
        """The run's learner on `env`, advised by `advisor` or judged by `evaluator`: the
        ones `make_env`, `make_advisor` and `make_evaluator` make, or what a caller wraps
        them in (the session worker adds the live view's scene broadcast and records the
        advice and the judgements, or supplies the person). The spec is a validated one
        (`validate`); SB3's DQN takes no advice."""
        if self.learner == "sb3-dqn":
            from learner.sb3_dqn import SB3DQNTrainer

            return SB3DQNTrainer(
                env, self.config, self.seed, list(callbacks), hyperparameters=self.sb3
            )
        from learner.trainer import Trainer

        return Trainer(
            env, self.config, advisor, self.make_strategy(), self.seed, list(callbacks),
            schedule=self.make_schedule(), evaluator=evaluator,
            feedback_weight=self.feedback_weight, feedback_method=self.feedback_method,
            rating_model_steps=self.rating_model_steps,
        )  # fmt: skip

    def make_schedule(self) -> Schedule | None:
        """The procedure control's schedule (None for other methods)."""
        if self.method != "procedure" or not self.schedule:
            return None
        from learner.procedure import Schedule

        try:
            return Schedule.load(self.schedule)
        except ValueError as error:
            raise RunSpecError("schedule", str(error)) from None


NUMERICS = tuple(leaf.name for leaf in leaves(RunSpec) if leaf.role == "numerics")
"""The leaves a session pins when it is created (`RunSpec.pinned`)."""
OPEN_NUMERICS = frozenset({"auto", 0})
"""A numerics value that leaves the choice to the machine."""

_DECLARED: list[type[RunSpec]] = []


def declared() -> type[RunSpec]:
    """The run's declaration: what every entry point reads, shows and stores runs with
    (the REST body and its schema, the flags, the export's columns, the audit). `RunSpec`,
    unless a class that extends it by fields is declared (`declare`)."""
    return _DECLARED[-1] if _DECLARED else RunSpec


@contextmanager
def declare(spec_type: type[RunSpec]) -> Iterator[type[RunSpec]]:
    """Read and show every run as `spec_type` (a subclass of `RunSpec` with more fields)
    while the block runs, in this process. A worker process the server starts is handed
    the declaration in force (so the class must be importable there)."""
    if not issubclass(spec_type, RunSpec):
        raise TypeError(f"{spec_type!r} does not extend RunSpec")
    _DECLARED.append(spec_type)
    try:
        yield spec_type
    finally:
        _DECLARED.remove(spec_type)


def run_flags(spec: RunSpec, normalized: bool = True) -> list[str]:
    """The command-line flags (`ideeprl batch`, `ideeprl train`) that describe `spec` beside
    its method: `--preset`, `--seed` and every field whose value is not the preset's. With
    `normalized`, both sides are compared after `normalized` (an unadvised run gives no
    advice options); without, as given (a batch's template, whose runs take several
    methods)."""
    base = type(spec).from_json({"preset": spec.preset, "method": spec.method})
    if normalized:
        spec, base = spec.normalized(), base.normalized()
    ours, theirs = spec.values(), base.values()
    parts = ["--preset", spec.preset]
    for leaf in leaves(type(spec)):
        value = ours[leaf.name]
        unchanged = value == theirs[leaf.name] and leaf.name != "seed"
        if leaf.name in ("method", "preset") or unchanged:
            continue
        parts += [leaf.flag, value if isinstance(value, str) else json.dumps(value)]
    return parts


def from_old_settings(settings: Mapping[str, Any], config: DQNConfig) -> RunSpec:
    """A run from an older checkpoint's metadata (before the run was one JSON document: an
    `advisor` and a `budget` beside the config, the strategy's options loose or in
    `strategy_options`, no scenario before it existed)."""
    if "method" in settings:
        return RunSpec.from_json({**settings, "config": config.to_dict()})
    advisor = settings.get("advisor", "none")
    learner = settings.get("learner", "dqn")
    method = "sb3-dqn" if learner == "sb3-dqn" else ("autonomous" if advisor == "none" else advisor)
    strategy = settings.get("strategy", "early")
    options = settings.get("strategy_options")
    if options is None:
        defaults = strategy_defaults(strategy)
        options = {name: settings[name] for name in defaults if name in settings}
    budget = settings.get("budget")
    if budget is not None and method not in UNADVISED:
        config = config.replace(advice_budget=int(budget))
    return RunSpec(
        method=cast(Method, method),  # checked by RunSpec itself
        seed=int(settings.get("seed", 0)),
        preset=settings.get("preset", "paper"),
        config=config,
        strategy=strategy,
        strategy_options=StrategyOptions(**options),
        advisor_checkpoint=settings.get("advisor_checkpoint"),
        error_rate=float(settings.get("error_rate", 0.0)),
        motion=settings.get("motion", "fast"),
        sort_rule=settings.get("sort_rule", "color"),
        scenario=ScenarioOptions.from_dict(settings.get("scenario")),
    )


def _task_preset(task: Any) -> Any:
    """The preset a run of this task starts from when it names none: the task's own (a
    task that cannot be had: the paper's, and `validate` names the task)."""
    try:
        return get_task(task).preset if isinstance(task, str) else "paper"
    except TaskError:
        return "paper"
