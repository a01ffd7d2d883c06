"""Bodies of the studies resource."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from study.schemas.design import NewStudyDesign, StudyDesign
from study.schemas.types import StudyName, Text, Texts


class StudyBase(BaseModel):
    model_config = ConfigDict(extra="forbid")

    description: Text = Field(default="", max_length=10_000)
    texts: Texts = Field(
        default_factory=dict,
        max_length=32,
        description="Per-study texts of the participant pages (consent, induction steps).",
    )


class StudyCreate(StudyBase):
    name: StudyName = Field(description="Unique name of the study (not blank).")
    design: NewStudyDesign | None = Field(
        default=None,
        description="An online study's design (conditions, targets, capacity, panel, check, "
        "questionnaire): the study gets a public link `/join/KEY` that assigns arrivals. "
        "Omitted: a lab study, its sessions made by hand.",
    )


class StudyUpdate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: StudyName | None = None
    description: Text | None = Field(default=None, max_length=10_000)
    texts: Texts | None = Field(default=None, max_length=32)
    design: NewStudyDesign | None = Field(
        default=None, description="A new design, whole; a lab study becomes an online one."
    )


class StudyPublic(StudyBase):
    model_config = ConfigDict(from_attributes=True)

    id: int
    name: str
    description: str = ""
    texts: dict[str, str] = Field(default_factory=dict)
    created_at: datetime
    session_count: int = 0
    design: StudyDesign | None = Field(
        default=None, description="The design as stored, every default written out."
    )
    join_url: str | None = Field(
        default=None, description="The study's public link (online studies): give it to the panel."
    )


class FittedAdvisorPublic(BaseModel):
    """An advisor model fitted to the study's people (`ideeprl fit`); a `fitted` session
    names it as `fitted:ID` in `run.fitted_model`."""

    id: int
    study_id: int
    created_at: datetime
    session_ids: list[int] = Field(description="The sessions whose advice it was fitted from.")
    summary: dict[str, Any] = Field(
        description="Error rates by what the arm held and by situation (station/held), the "
        "decision times' median and sigma, the share of sessions that stopped early; a "
        "fitted evaluator's (kind evaluative): error rates by move (right or wrong) and "
        "situation, the share of Good answers and of turns without one."
    )
    model: dict[str, Any] = Field(
        description="The whole model (`learner.fitted.FittedModel`, versioned JSON)."
    )


class ConditionCounts(BaseModel):
    condition: str
    target: int
    completed: int
    in_progress: int
    declined: int
    excluded: int
    timed_out: int


class Preview(BaseModel):
    session_id: int
    participant_url: str


class SessionDisk(BaseModel):
    session_id: int
    checkpoint_bytes: int = Field(description="The session's checkpoint folder.")


class StudyDisk(BaseModel):
    """What a study keeps on disk, beside its database rows."""

    study_id: int
    total_bytes: int
    checkpoint_bytes: int
    report_bytes: int = Field(description="Its report and any export being packed.")
    sessions: list[SessionDisk]
