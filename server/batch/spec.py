"""What a batch runs: N agents per method, their seeds, and the session each becomes.

A run is identified by its study, method, seed and full configuration (never by a name or
a counter), so running the same batch again finds the runs it already has: the finished
ones are skipped, the interrupted ones resume, only the missing ones are created.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from learner.run import MOTIONS
from learner.strategies import STRATEGY_NAMES
from server.schemas.sessions import Scenario, SessionCreate, StrategyOptions
from sim.scenario import ScenarioOptions

BATCH_METHODS: tuple[str, ...] = ("autonomous", "agent", "oracle", "random", "sb3-dqn")
"""Methods a batch can run: every machine advisor, no advisor at all, and Stable-Baselines3's
DQN (an independent baseline learner, the optional `sb3` extra)."""
UNADVISED: tuple[str, ...] = ("autonomous", "sb3-dqn")
"""Methods without an advisor (no strategy, no advice budget)."""

MAX_SEED = 2**31 - 1
ADVISOR_SEED_OFFSET = 100_000
"""The advisor trained for `agent` runs has seed `base_seed + ADVISOR_SEED_OFFSET`: apart from
every run's seed, and unchanged when the batch grows."""
MAX_AGENTS = 10_000


class BatchError(ValueError):
    """A batch cannot run as asked; the message says what to change."""


@dataclass(frozen=True)
class BatchSpec:
    """The runs of one batch: `agents` learners for each of `methods`, all on the same
    settings, agent i of every method on the same seed (so runs pair up across methods)."""

    methods: tuple[str, ...] = ("autonomous", "agent")
    """Methods to run (`BATCH_METHODS`); the paper compares autonomous and agent."""
    agents: int = 10
    """Learners per method (the paper's ten)."""
    base_seed: int = 0
    """Agent i of every method gets seed `base_seed + i`."""
    label: str = "baselines"
    """The batch's name, stored as every run's session label."""
    preset: str = "paper"
    """Learner config preset (`paper`, `modern`)."""
    config: dict[str, Any] = field(default_factory=dict)
    """Learner config fields overriding the preset (e.g. `pretraining_steps`, `batch_size`)."""
    episodes: int | None = None
    """Training episodes per run; None: the preset's (300)."""
    max_episode_steps: int | None = None
    """Truncation per episode; None: the preset's (250)."""
    advice_budget: int | None = None
    """Advice per advised run; None: the preset's (100)."""
    strategy: str = "early"
    """Advising strategy of advised runs (the paper's early advising)."""
    strategy_options: dict[str, Any] = field(default_factory=dict)
    """The strategy's options (`interval`, `threshold`); unset ones take its defaults."""
    oracle_error_rate: float = 0.0
    """Chance that the `oracle` advisor names a wrong action."""
    advisor_checkpoint: str | None = None
    """Trained learner checkpoint that advises `agent` runs; None: a batch trains one first
    (autonomous, same settings, seed `base_seed + ADVISOR_SEED_OFFSET`), as the paper did."""
    motion: str = "fast"
    """`fast` (poses set directly) or `physics`; batch runs need no one to watch."""
    sort_rule: str | dict[str, str] = "color"
    """The sorting rule (`color`, `shape`, or a map of all six objects to a side)."""
    scenario: dict[str, Any] = field(default_factory=dict)
    """Scenario options of every run (`sim.ScenarioOptions`: reward scheme, realism rates)."""
    reward_schemes: dict[str, str] = field(default_factory=dict)
    """A reward scheme for some methods only, over `scenario`'s: how the authors compared
    their methods (`autonomous` under `authors-autonomous`, `agent` under
    `authors-interactive`). The report flags such a comparison. The advisor trained for
    `agent` runs is an autonomous run and takes the autonomous scheme."""

    def __post_init__(self) -> None:
        unknown = [m for m in self.methods if m not in BATCH_METHODS]
        if unknown:
            hint = (
                " (human sessions need a participant: create them through the API)"
                if "human" in unknown
                else ""
            )
            raise BatchError(
                f"unknown method(s) {', '.join(map(repr, unknown))}{hint}; a batch runs "
                f"{', '.join(BATCH_METHODS)}"
            )
        if not self.methods:
            raise BatchError(f"no method to run; choose from {', '.join(BATCH_METHODS)}")
        if "sb3-dqn" in self.methods:
            from learner.sb3_dqn import MISSING, available

            if not available():
                raise BatchError(MISSING)
        if len(set(self.methods)) != len(self.methods):
            raise BatchError(f"methods repeat: {', '.join(self.methods)}; name each once")
        if not 1 <= self.agents <= MAX_AGENTS:
            raise BatchError(f"agents must be between 1 and {MAX_AGENTS}, got {self.agents}")
        top = self.base_seed + ADVISOR_SEED_OFFSET
        if self.base_seed < 0 or top > MAX_SEED:
            raise BatchError(
                f"base seed must be between 0 and {MAX_SEED - ADVISOR_SEED_OFFSET}, "
                f"got {self.base_seed}"
            )
        for name, value, valid in (
            ("strategy", self.strategy, STRATEGY_NAMES),
            ("motion", self.motion, MOTIONS),
        ):
            if value not in valid:
                raise BatchError(f"unknown {name} {value!r}; choose from {', '.join(valid)}")
        if not 0.0 <= self.oracle_error_rate <= 1.0:
            raise BatchError(
                f"oracle error rate must be between 0 and 1, got {self.oracle_error_rate}"
            )
        strays = sorted(set(self.reward_schemes) - set(self.methods))
        if strays:
            raise BatchError(
                f"a reward scheme is given for {', '.join(strays)}, which the batch does not run"
            )
        for method in self.methods:
            try:
                ScenarioOptions.from_dict(self.scenario_of(method))
            except ValueError as error:
                raise BatchError(str(error)) from None
        if self.advisor_checkpoint is not None:
            if "agent" not in self.methods:
                raise BatchError("an advisor checkpoint is only used by the 'agent' method")
            if not Path(self.advisor_checkpoint).is_file():
                raise BatchError(
                    f"no advisor checkpoint at {self.advisor_checkpoint}; give the path of a "
                    "trained learner's checkpoint (e.g. a session's final.pt), or leave it out "
                    "to train the advisor first"
                )

    def scenario_of(self, method: str) -> dict[str, Any]:
        """The scenario options of a method's runs."""
        scenario = dict(self.scenario)
        if method in self.reward_schemes:
            scenario["reward_scheme"] = self.reward_schemes[method]
        return scenario

    @property
    def trains_advisor(self) -> bool:
        return "agent" in self.methods and self.advisor_checkpoint is None

    def seed(self, index: int) -> int:
        """The seed of agent `index` (from 0) of every method."""
        return self.base_seed + index

    @property
    def advisor_seed(self) -> int:
        return self.base_seed + ADVISOR_SEED_OFFSET


@dataclass(frozen=True)
class Run:
    """One learner of the batch, before or after its session exists."""

    method: str
    """The session's method."""
    index: int
    """Agent number within its method, from 0; -1 for the advisor."""
    seed: int
    """The session's seed."""

    @property
    def is_advisor(self) -> bool:
        return self.index < 0

    @property
    def name(self) -> str:
        return "advisor" if self.is_advisor else f"{self.method} #{self.index + 1}"


def plan_runs(spec: BatchSpec) -> list[Run]:
    """Every run of the batch: the advisor first (when one is trained), then agent by agent,
    each agent's methods together, so a batch cut short still has paired runs."""
    runs = [Run("autonomous", -1, spec.advisor_seed)] if spec.trains_advisor else []
    for index in range(spec.agents):
        runs += [Run(method, index, spec.seed(index)) for method in spec.methods]
    return runs


def session_body(spec: BatchSpec, run: Run, advisor_checkpoint: str | None) -> SessionCreate:
    """The session a run becomes; `advisor_checkpoint` for `agent` runs (an absolute path)."""
    advised = run.method not in UNADVISED
    return SessionCreate(
        method=run.method,  # type: ignore[arg-type]
        seed=run.seed,
        label=f"{spec.label} advisor" if run.is_advisor else spec.label,
        preset=spec.preset,
        config=dict(spec.config),
        episodes=spec.episodes,
        max_episode_steps=spec.max_episode_steps,
        sort_rule=spec.sort_rule,
        strategy=spec.strategy if advised else "early",  # type: ignore[arg-type]
        strategy_options=StrategyOptions(**(spec.strategy_options if advised else {})),
        advice_budget=spec.advice_budget if advised else None,
        advisor_checkpoint=advisor_checkpoint if run.method == "agent" else None,
        oracle_error_rate=spec.oracle_error_rate if run.method == "oracle" else 0.0,
        motion=spec.motion,  # type: ignore[arg-type]
        scenario=Scenario(**spec.scenario_of(run.method)),
    )
