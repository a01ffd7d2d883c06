"""What a batch runs: N agents per method, their seeds, and the session each becomes.

A run is identified by its study, method, seed and full configuration (never by a name or
a counter), so running the same batch again finds the runs it already has: the finished
ones are skipped, the interrupted ones resume, only the missing ones are created.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from learner.fields import FieldError
from learner.run import RunSpec

BATCH_METHODS: tuple[str, ...] = (
    "autonomous", "agent", "oracle", "random", "procedure", "sb3-dqn", "fitted", "replayed",
)  # fmt: skip
"""Methods a batch can run: every machine advisor (an advisor fitted to people included), no
advisor at all, the procedure control of an advised method (`control_of`), Stable-Baselines3's
DQN (an independent baseline learner, the optional `sb3` extra), and `replayed`: each
completed session of another study re-run under the batch's run, fed its advice by order
(`study.services.replays`)."""
CONTROLLED = ("agent", "oracle", "random")
"""The advised (or, under evaluative feedback, judged) methods a `procedure` control can
follow."""

MAX_SEED = 2**31 - 1
ADVISOR_SEED_OFFSET = 100_000
"""The advisor trained for `agent` runs has seed `base_seed + ADVISOR_SEED_OFFSET`: apart from
every run's seed, and unchanged when the batch grows."""
MAX_AGENTS = 10_000


class BatchError(ValueError):
    """A batch cannot run as asked; the message says what to change."""


@dataclass(frozen=True)
class BatchSpec:
    """The runs of one batch: `agents` learners for each of `methods`, all described by one
    `template` run (the same settings), with some fields changed for some methods
    (`per_method`), agent i of every method on seed `template.seed + i` (so runs pair up).
    Only what is the batch's own is declared here; every run field is `RunSpec`'s."""

    template: RunSpec = field(default_factory=RunSpec)
    """The run every method's agents share; its `method` is each method's, its `seed` the
    base seed."""
    methods: tuple[str, ...] = ("autonomous", "agent")
    """Methods to run (`BATCH_METHODS`); the paper compares autonomous and agent."""
    agents: int = 10
    """Learners per method (the paper's ten)."""
    label: str = "baselines"
    """The batch's name, stored as every run's session label."""
    per_method: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """Fields of the template changed for one method, by leaf name: how the authors compared
    (`{"autonomous": {"reward_scheme": "authors-autonomous"}, "agent": {"reward_scheme":
    "authors-interactive"}}`). The report flags such a comparison. The advisor trained for
    `agent` runs is an autonomous run and takes the autonomous changes."""
    control_of: str = "agent"
    """The advised method whose runs the `procedure` runs follow: agent i's control replays
    the schedule of that method's agent i (same seed), with its settings."""
    replay_study: int | None = None
    """The study whose completed sessions the `replayed` method re-runs (required with it)."""
    replay_methods: tuple[str, ...] = ("human",)
    """Which of its sessions: those of these methods (people's advice by default)."""
    replay_sources: tuple[int, ...] = ()
    """The sessions the `replayed` runs replay, in id order, found in the database when the
    batch runs (`completed_sources`); replayed run i gets seed `base_seed + i`."""

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
        if ("replayed" in self.methods) != (self.replay_study is not None):
            raise BatchError(
                "the replayed method needs --replay-study ID, the study whose completed "
                "sessions it re-runs"
                if self.replay_study is None
                else "--replay-study is for the replayed method: add it to --methods"
            )
        if len(set(self.methods)) != len(self.methods):
            raise BatchError(f"methods repeat: {', '.join(self.methods)}; name each once")
        if not 1 <= self.agents <= MAX_AGENTS:
            raise BatchError(f"agents must be between 1 and {MAX_AGENTS}, got {self.agents}")
        top = self.base_seed + ADVISOR_SEED_OFFSET + max(self.agents, len(self.replay_sources))
        if top > MAX_SEED:
            raise BatchError(
                f"the base seed must be at most {MAX_SEED - ADVISOR_SEED_OFFSET - self.agents}"
            )
        strays = sorted(set(self.per_method) - set(self.methods))
        if strays:
            raise BatchError(
                f"settings are given for {', '.join(strays)}, which the batch does not run"
            )
        if "procedure" in self.methods and (
            self.control_of not in CONTROLLED or self.control_of not in self.methods
        ):
            raise BatchError(
                "the procedure control follows an advised method of the batch "
                f"({', '.join(CONTROLLED)}); --control-of {self.control_of} is not among "
                "--methods"
            )
        for method in self.methods:
            self.spec_of(method, self.base_seed)  # every method's run checked before any runs
        fitted = self.template.fitted_model
        if fitted is not None and "fitted" not in self.methods:
            raise BatchError("a fitted model is only used by the 'fitted' method")
        if self.template.error_rate and "oracle" not in self.methods:
            raise BatchError("an error rate is only used by the 'oracle' method")
        if "fitted" in self.methods:
            from learner.fitted import read_model
            from learner.fitted_ratings import read_evaluator_model

            evaluative = self.template.feedback == "evaluative"
            try:
                (read_evaluator_model if evaluative else read_model)(fitted or "")
            except ValueError as error:
                raise BatchError(f"fitted: {error}") from None
        checkpoint = self.template.advisor_checkpoint
        if checkpoint is not None:
            if "agent" not in self.methods:
                raise BatchError("an advisor checkpoint is only used by the 'agent' method")
            if not Path(checkpoint).is_file():
                raise BatchError(
                    "no advisor checkpoint at the path given; give the path of a trained "
                    "learner's checkpoint (e.g. a session's final.pt), or leave it out to "
                    "train the advisor first"
                )

    @property
    def base_seed(self) -> int:
        return self.template.seed

    def spec_of(self, method: str, seed: int) -> RunSpec:
        """The run of one of `method`'s agents (or of the advisor) on `seed`, checked."""
        changes = dict(self.per_method.get(method, {}))
        if method == "procedure":  # the control runs with its advised method's settings
            changes = {**self.per_method.get(self.control_of, {}), **changes}
        try:
            spec = self.template.with_values(changes) if changes else self.template
            spec = spec.replace(
                method=method,
                seed=seed,
                advisor_checkpoint=spec.advisor_checkpoint if method == "agent" else None,
                schedule="-" if method == "procedure" else None,  # written once its pair ran
                fitted_model=spec.fitted_model if method == "fitted" else None,
            )
            if method == "agent" and spec.advisor_checkpoint is None:
                spec = spec.replace(advisor_checkpoint="-")  # filled in once the advisor trained
            return spec.validate()
        except FieldError as error:
            raise BatchError(f"{method}: {error}") from None

    @property
    def trains_advisor(self) -> bool:
        return "agent" in self.methods and self.template.advisor_checkpoint is None

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
    source: int | None = None
    """A `replayed` run's source session (whose advice it is fed)."""

    @property
    def is_advisor(self) -> bool:
        return self.index < 0

    @property
    def name(self) -> str:
        if self.source is not None:
            return f"{self.method} #{self.index + 1} (of session {self.source})"
        return "advisor" if self.is_advisor else f"{self.method} #{self.index + 1}"


def plan_runs(spec: BatchSpec) -> list[Run]:
    """Every run of the batch: the advisor first (when one is trained), then agent by agent,
    each agent's methods together, so a batch cut short still has paired runs."""
    runs = [Run("autonomous", -1, spec.advisor_seed)] if spec.trains_advisor else []
    methods = [m for m in spec.methods if m != "replayed"]
    for index in range(spec.agents):
        runs += [Run(method, index, spec.seed(index)) for method in methods]
    if "replayed" in spec.methods:
        runs += [
            Run("replayed", index, spec.seed(index), source)
            for index, source in enumerate(spec.replay_sources)
        ]
    return runs


def run_spec(spec: BatchSpec, run: Run, advisor_checkpoint: str | None) -> RunSpec:
    """The run a batch run is; `advisor_checkpoint` for `agent` runs (an absolute path)."""
    described = spec.spec_of(run.method, run.seed)
    if run.method == "agent":
        described = described.replace(advisor_checkpoint=advisor_checkpoint or "-")
    return described
