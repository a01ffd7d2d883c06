"""Bodies of the studies resource."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, ConfigDict, Field


class StudyBase(BaseModel):
    model_config = ConfigDict(extra="forbid")

    description: str = Field(default="", max_length=10_000)
    texts: dict[str, str] = Field(
        default_factory=dict,
        description="Per-study texts of the participant pages (consent, induction steps).",
    )


class StudyCreate(StudyBase):
    name: str = Field(min_length=1, max_length=200, description="Unique name of the study.")


class StudyUpdate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(default=None, min_length=1, max_length=200)
    description: str | None = Field(default=None, max_length=10_000)
    texts: dict[str, str] | None = None


class StudyPublic(StudyBase):
    model_config = ConfigDict(from_attributes=True)

    id: int
    name: str
    created_at: datetime
    session_count: int = 0
