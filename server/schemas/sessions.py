"""Bodies of the sessions resource: what a researcher sets, and what they read back."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from learner.config import PRESETS
from learner.docstrings import field_docstrings
from learner.run import MOTIONS
from learner.strategies import STRATEGY_NAMES
from server.db.models import Method
from server.schemas.types import Int, Key, Number
from sim.rewards import REWARD_SCHEMES
from sim.scenario import ScenarioOptions

SCENARIO_DOCS = field_docstrings(ScenarioOptions)

# The names are the learner's and the scenario's, never restated here.
Strategy = Literal[STRATEGY_NAMES]  # type: ignore[valid-type]
Motion = Literal[MOTIONS]  # type: ignore[valid-type]
RewardSchemeName = Literal[REWARD_SCHEMES]  # type: ignore[valid-type]


class Scenario(BaseModel):
    """The scenario's options (`sim.ScenarioOptions`; a test keeps the two the same)."""

    model_config = ConfigDict(extra="forbid")

    reward_scheme: RewardSchemeName = Field(
        default="paper", description=SCENARIO_DOCS["reward_scheme"]
    )
    grasp_failure_rate: Number = Field(
        default=0.0, ge=0.0, le=1.0, description=SCENARIO_DOCS["grasp_failure_rate"]
    )
    knock_off_rate: Number = Field(
        default=0.0, ge=0.0, le=1.0, description=SCENARIO_DOCS["knock_off_rate"]
    )


class StrategyOptions(BaseModel):
    """The advising strategy's options besides its budget (`learner.run.STRATEGY_OPTIONS`;
    a test keeps the two the same). Unset ones take the strategy's defaults; one the
    chosen strategy does not take is a 422."""

    model_config = ConfigDict(extra="forbid")

    interval: Int | None = Field(
        default=None, ge=1, le=100_000, description="alternating: advise every Nth step (2)."
    )
    threshold: Number | None = Field(
        default=None,
        ge=0.0,
        description="importance, mistake_correcting: the advisor's Q-value spread (max - min) "
        "from which a state is important (0.1).",
    )

    def given(self) -> dict[str, Any]:
        """The options set, by name."""
        return self.model_dump(exclude_none=True)


class SessionCreate(BaseModel):
    """One learner's run. Unset fields take the paper's defaults."""

    model_config = ConfigDict(extra="forbid")

    method: Method = Field(
        description="Who advises: autonomous, agent, human, oracle, random; or sb3-dqn, "
        "Stable-Baselines3's DQN unadvised (an independent baseline; needs the sb3 extra)."
    )
    seed: Int = Field(default=0, ge=0, le=2**31 - 1, description="Fixes scene, network, sampling.")
    label: str = Field(default="", max_length=200, description="Free text, e.g. a batch name.")
    preset: str = Field(
        default="paper",
        max_length=40,
        description=f"Learner config preset ({', '.join(PRESETS)}).",
    )
    config: dict[Key, Any] = Field(
        default_factory=dict,
        max_length=100,
        description="Learner config fields overriding the preset.",
    )
    episodes: Int | None = Field(
        default=None, ge=1, le=100_000, description="Training episodes (default: the preset's)."
    )
    max_episode_steps: Int | None = Field(
        default=None, ge=1, le=10_000, description="Truncation (default: the preset's)."
    )
    sort_rule: (
        Annotated[str, Field(max_length=40)]
        | Annotated[dict[Key, Annotated[str, Field(max_length=10)]], Field(max_length=12)]
    ) = Field(default="color", description='"color", "shape", or a map {"cube/red": "left", ...}.')
    strategy: Strategy = Field(default="early", description="Advising strategy (advised methods).")
    strategy_options: StrategyOptions = Field(
        default_factory=StrategyOptions,
        description="The strategy's options (interval, threshold); unset: its defaults.",
    )
    advice_budget: Int | None = Field(
        default=None, ge=0, le=100_000, description="Advice in all (default: the preset's)."
    )
    advisor_checkpoint: str | None = Field(
        default=None,
        max_length=1000,
        description="The advisor (method agent): `session:ID`, a session of this installation "
        "whose final checkpoint advises, or the path of a checkpoint file under the data folder.",
    )
    oracle_error_rate: Number = Field(
        default=0.0, ge=0.0, le=1.0, description="Chance that the oracle advises wrongly."
    )
    motion: Motion | None = Field(
        default=None, description="physics (default for human) or fast (default otherwise)."
    )
    scenario: Scenario = Field(
        default_factory=Scenario, description="Reward scheme and realism rates."
    )
    participant: str | None = Field(
        default=None,
        min_length=1,
        max_length=64,
        pattern=r"^[A-Za-z0-9_-]+$",
        description="Pseudonym of the participant (human); generated when omitted.",
    )
    keep_replay_memory: bool | None = Field(
        default=None,
        strict=True,
        description="Keep the replay memory in the final checkpoint (default: the server's "
        "keep_replay_memory setting). Without it the final checkpoint holds the network and "
        "what an advisor needs, a few MB instead of about 250 MB at paper scale.",
    )
    idle_limit_s: Number | None = Field(
        default=None, gt=0, description="Seconds without advice before abandoning (human)."
    )


class SessionPublic(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    study_id: int
    label: str
    method: str
    seed: int
    config: dict[str, Any]
    sort_rule: str | dict[str, str]
    strategy: str | None
    strategy_options: dict[str, Any] | None = Field(
        default=None, description="The strategy's options, defaults spelled out."
    )
    advice_budget: int
    advisor_checkpoint: str | None
    oracle_error_rate: float | None
    motion: str
    scenario: dict[str, Any]
    episodes: int
    max_episode_steps: int
    idle_limit_s: float | None
    keep_replay_memory: bool | None = None
    participant: str | None = None
    participant_url: str | None = None
    status: str
    status_detail: str
    progress: dict[str, Any]
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    worker_pid: int | None
    checkpoint_step: int
    consented_at: datetime | None = Field(
        default=None, description="When the participant consented (human sessions)."
    )
    declined_at: datetime | None = Field(
        default=None, description="When the participant last declined (human sessions)."
    )
    induction_done_at: datetime | None = Field(
        default=None, description="When they finished the induction: advice may be asked."
    )
    texts_version: int | None = Field(
        default=None, description="Version of the study's texts the participant was shown."
    )


class SessionCreated(SessionPublic):
    participant_token: str | None = Field(
        default=None, description="The participant's secret; their link is participant_url."
    )


class Progress(BaseModel):
    """Live progress of a session (from its worker while it runs, else the last saved)."""

    session_id: int
    status: str
    phase: str | None = None
    global_step: int = 0
    episode: int = 0
    episodes: int = 0
    epsilon: float | None = None
    collected_reward: float = 0.0
    last_episode_reward: float | None = None
    advice_given: int = 0
    advice_budget: int = 0
    advice_left: int = 0
    advice_wanted: bool = False
    queued: bool = Field(
        default=False,
        description="Advice over; waiting in the server's queue for a free trainer slot.",
    )
    consented: bool = Field(default=False, description="The participant consented (human).")


class EpisodePublic(BaseModel):
    """One episode (the learner's `EpisodeRecord`); the column dictionary explains each."""

    model_config = ConfigDict(from_attributes=True)

    phase: str
    episode: int
    collected_reward: float
    steps: int
    placed_correct: int
    misplaced: int
    lost: int
    success: bool
    advised_steps: int
    epsilon: float
    mean_loss: float | None
    first_global_step: int
    last_global_step: int
    wall_time: float


class AdvicePublic(BaseModel):
    """One advice, without its image (GET .../advice/INDEX.png has it)."""

    model_config = ConfigDict(from_attributes=True)

    advice_index: int
    global_step: int
    advisor: str
    action: int
    greedy_action: int | None
    response_time_s: float
    decision_time_s: float | None = None
    requested_at: datetime
    answered_at: datetime
