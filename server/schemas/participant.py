"""Bodies of the participant endpoints (the advising page of a human session)."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, ConfigDict, Field

from server.schemas.types import Int, Number
from sim.actions import ACTION_NAMES

MAX_DECISION_TIME_S = 86_400.0
"""A decision time beyond a day is a broken clock, not a decision."""


class AdviceCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    advice_index: Int = Field(ge=0, le=2**31 - 1, description="Index of the advice (0-based).")
    action: Int = Field(ge=0, le=3, description="0 grab, 1 move right, 2 move left, 3 drop.")
    decision_time_s: Number | None = Field(
        default=None,
        ge=0.0,
        le=MAX_DECISION_TIME_S,
        allow_inf_nan=False,
        description="Seconds from the moment the page's buttons became active to the click or "
        "key, on the browser's monotonic clock (performance.now()); stored beside the "
        "server's response_time_s, which also counts the 3-D replay and the network.",
    )


class HistoryItem(BaseModel):
    advice_index: int
    action: int
    action_name: str
    reward: float | None = None


class HeldObject(BaseModel):
    shape: str
    color: str


class ParticipantState(BaseModel):
    """Everything the advising page shows; `version` grows with every change (long-poll)."""

    session_id: int
    status: str
    message: str = ""
    version: int
    advice_wanted: bool
    advice_index: int | None = None
    observation_png: str | None = Field(
        default=None, description="Base64 PNG (64x64, lossless) of what the learner sees."
    )
    robot_moving: bool
    held: HeldObject | None = Field(
        default=None, description="What the robot holds at this request (None: nothing)."
    )
    station: str | None = Field(
        default=None, description="Where the arm is at this request: center, left, right."
    )
    advice_budget: int
    advice_given: int
    advice_left: int
    last_reward: float | None = None
    episode: int = 0
    stage: str | None = None
    ready: bool = Field(
        default=False, description="Consent and induction done: advice may be asked."
    )
    queued: bool = Field(
        default=False, description="Advice over; the learner waits for a free trainer slot."
    )
    history: list[HistoryItem] = Field(default_factory=list)
    action_names: list[str] = Field(default_factory=lambda: list(ACTION_NAMES))


class AdviceReceipt(BaseModel):
    advice_index: int
    action: int
    duplicate: bool = Field(description="True if this advice had been received already.")
    response_time_s: float
    version: int = Field(description="State version after this advice: long-poll after it.")
    state: ParticipantState | None = Field(
        default=None, description="With ?wait=S: the state after what happened next."
    )


class ConsentCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    agree: bool = Field(description="True: consent; False: decline.")
    texts_version: int | None = Field(
        default=None,
        ge=1,
        le=2**31 - 1,
        description="Id of the texts version shown (GET /api/participant/consent); default: "
        "the texts as shown now.",
    )


class ConsentState(BaseModel):
    """What the participant read and decided, as the server recorded it."""

    texts_version: int = Field(description="Id of the texts version shown now or consented to.")
    texts: dict[str, str] = Field(description="The texts of that version, exactly as shown.")
    consented_at: datetime | None = None
    declined_at: datetime | None = None
    induction_done_at: datetime | None = None


class Readiness(BaseModel):
    """How far the robot's random pretraining is before the first turn (the page polls)."""

    status: str
    steps_done: int = Field(description="Environment steps taken so far.")
    steps_before_first_turn: int = Field(description="Random steps before the first advice.")
    ready: bool = Field(description="The robot waits for (or already asks) the first advice.")
