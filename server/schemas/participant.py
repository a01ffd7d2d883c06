"""Bodies of the participant endpoints (the advising page of a human session)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from server.schemas.types import Int


class AdviceCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    advice_index: Int = Field(ge=0, le=2**31 - 1, description="Index of the advice (0-based).")
    action: Int = Field(ge=0, le=3, description="0 grab, 1 move right, 2 move left, 3 drop.")


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
    phase: str | None = None
    history: list[HistoryItem] = Field(default_factory=list)
    action_names: list[str] = Field(
        default_factory=lambda: ["grab", "move right", "move left", "drop"]
    )


class AdviceReceipt(BaseModel):
    advice_index: int
    action: int
    duplicate: bool = Field(description="True if this advice had been received already.")
    response_time_s: float
    version: int = Field(description="State version after this advice: long-poll after it.")
    state: ParticipantState | None = Field(
        default=None, description="With ?wait=S: the state after what happened next."
    )
