"""Bodies of the dashboard's episode playback (`server.routes.playback`): the episodes
of a session, an open playback's steps and advice, and the step the 3-D view draws."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from study.schemas.types import MAX_ID


class EpisodeRow(BaseModel):
    stage: str
    episode: int
    steps: int
    collected_reward: float
    advised_steps: int
    playable: bool
    """It has a reset seed: it can be rerun."""


class PlaybackOpened(BaseModel):
    id: str
    url: str
    """Where the page reads the playback."""


class StepShown(BaseModel):
    index: int
    """0-based position in the episode."""
    step: int
    """The episode's step number (from 1)."""
    global_step: int
    action: int
    action_name: str
    action_source: str
    reward: float
    image_url: str
    """The 64x64 image the learner saw when the action was chosen (the rerun's)."""


class AdviceShown(BaseModel):
    advice_index: int
    global_step: int
    index: int
    """The 0-based position of its step in the episode."""
    action: int
    action_name: str
    advisor: str
    decision_time_s: float | None
    response_time_s: float
    image_url: str
    """The image the advisor was shown, as stored with the advice."""


class PlaybackState(BaseModel):
    id: str
    session_id: int
    method: str
    stage: str
    episode: int
    state: Literal["rerunning", "ready", "failed"]
    detail: str
    """Why it failed; or where the rerun's rewards differ from the logged ones."""
    collected_reward: float
    steps: list[StepShown] = Field(default_factory=list)
    """Filled when the rerun is ready."""
    end_image_url: str = ""
    """The image after the last step (when ready): `steps/N.png`, N the number of steps."""
    advice: list[AdviceShown] = Field(default_factory=list)


class Show(BaseModel):
    index: int = Field(ge=0, le=MAX_ID)
    """0-based step whose decision the 3-D view draws; the number of steps: the end."""
