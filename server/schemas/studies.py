"""Bodies of the studies resource."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

from server.schemas.types import Key

MAX_TEXT = 50_000
"""Characters of one page text (the consent form is the longest, about 3,000)."""
Texts = dict[Key, Annotated[str, Field(max_length=MAX_TEXT)]]


class StudyBase(BaseModel):
    model_config = ConfigDict(extra="forbid")

    description: str = Field(default="", max_length=10_000)
    texts: Texts = Field(
        default_factory=dict,
        max_length=32,
        description="Per-study texts of the participant pages (consent, induction steps).",
    )


class StudyCreate(StudyBase):
    name: str = Field(min_length=1, max_length=200, description="Unique name of the study.")


class StudyUpdate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(default=None, min_length=1, max_length=200)
    description: str | None = Field(default=None, max_length=10_000)
    texts: Texts | None = Field(default=None, max_length=32)


class StudyPublic(StudyBase):
    model_config = ConfigDict(from_attributes=True)

    id: int
    name: str
    created_at: datetime
    session_count: int = 0
