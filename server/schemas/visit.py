"""What an online study asks around the advice: the comprehension check after the
induction and the questionnaire after it (`../shared/SPEC.md` section 5 gives the defaults).

Contract between the design (`server.schemas.design`) and the visit pages: the design
holds one `CheckSpec | None` and one `QuestionnaireSpec | None`; `CheckSpec.default()` and
`QuestionnaireSpec.default()` are the SPEC's defaults. Torch-free: the analysis scores the
answers with the same definitions.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class CheckSpec(BaseModel):
    """The comprehension check: questions with correct answers and a number of tries;
    failing every try ends the visit as `excluded`."""

    model_config = ConfigDict(extra="forbid")

    tries: int = Field(default=2, ge=1, le=10)

    @classmethod
    def default(cls) -> CheckSpec:
        """The SPEC's default check (the study's sort rule decides the right answers)."""
        return cls()


class QuestionnaireSpec(BaseModel):
    """The questionnaire after the advice: configurable items plus the built-in scales."""

    model_config = ConfigDict(extra="forbid")

    @classmethod
    def default(cls) -> QuestionnaireSpec:
        """The SPEC's default: NASA-TLX raw, the trust checklist, optional demographics."""
        return cls()
