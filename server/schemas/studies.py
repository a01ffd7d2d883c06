"""Bodies of the studies resource."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

from server.schemas.types import Key, Text

MAX_TEXT = 50_000
"""Characters of one page text (the consent form is the longest, about 3,000)."""
Texts = dict[Key, Annotated[Text, Field(max_length=MAX_TEXT)]]


class StudyBase(BaseModel):
    model_config = ConfigDict(extra="forbid")

    description: Text = Field(default="", max_length=10_000)
    texts: Texts = Field(
        default_factory=dict,
        max_length=32,
        description="Per-study texts of the participant pages (consent, induction steps).",
    )


class StudyCreate(StudyBase):
    name: Text = Field(min_length=1, max_length=200, description="Unique name of the study.")


class StudyUpdate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: Text | None = Field(default=None, min_length=1, max_length=200)
    description: Text | None = Field(default=None, max_length=10_000)
    texts: Texts | None = Field(default=None, max_length=32)


class StudyPublic(StudyBase):
    model_config = ConfigDict(from_attributes=True)

    id: int
    name: str
    description: str = ""
    texts: dict[str, str] = Field(default_factory=dict)
    created_at: datetime
    session_count: int = 0


class FittedAdvisorPublic(BaseModel):
    """An advisor model fitted to the study's people (`ideeprl fit`); a `fitted` session
    names it as `fitted:ID` in `run.fitted_model`."""

    id: int
    study_id: int
    created_at: datetime
    session_ids: list[int] = Field(description="The sessions whose advice it was fitted from.")
    summary: dict[str, Any] = Field(
        description="Error rates by what the arm held and by situation (station/held), the "
        "decision times' median and sigma, the share of sessions that stopped early."
    )
    model: dict[str, Any] = Field(
        description="The whole model (`learner.fitted.FittedModel`, versioned JSON)."
    )
