"""An online study's design: its conditions, targets, capacity, panel setting, check,
questionnaire and outcome codes (`../shared/SPEC.md` section 5). Stored whole, defaults
written out, in `studies.design`."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from server.schemas.visit import CheckSpec, QuestionnaireSpec


class StudyDesign(BaseModel):
    model_config = ConfigDict(extra="forbid")

    check: CheckSpec | None = Field(default_factory=CheckSpec.default)
    questionnaire: QuestionnaireSpec | None = Field(default_factory=QuestionnaireSpec.default)
