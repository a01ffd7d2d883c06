"""Bodies of a study's report (`server.routes.reports`, and the dashboard's copy)."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool

from analysis.baseline import AUTO
from study.schemas.types import MAX_ID, WHOLE, Text


class ReportCreate(BaseModel):
    """Which sessions the report covers; by default the study's finished sessions except
    advisors, with autonomous DeepRL as the baseline when present."""

    model_config = ConfigDict(extra="forbid")

    sessions: list[Annotated[int, Field(strict=True, ge=1, le=MAX_ID), WHOLE]] | None = Field(
        default=None,
        min_length=1,
        max_length=10_000,
        description="These sessions only (any status).",
    )
    methods: list[Annotated[Text, Field(max_length=40)]] | None = Field(
        default=None, min_length=1, max_length=20, description="These methods."
    )
    label: Text | None = Field(default=None, max_length=200, description="This label only.")
    baseline: Text = Field(
        default=AUTO,
        max_length=40,
        description="auto (autonomous when present), none, or a method.",
    )
    n_episodes: Annotated[int, Field(strict=True, ge=1, le=100_000), WHOLE] | None = Field(
        default=None, description="First N episodes of every agent."
    )
    title: Text | None = Field(default=None, max_length=200, description="Report title.")
    allow_mismatch: StrictBool = Field(
        default=False,
        description="Also give the t-tests of methods that ran under different settings "
        "(reward scheme, learner, scenario); the report's warning stays.",
    )
    reference: Literal["authors"] | None = Field(
        default=None, description="authors: draw the authors' published curves on Figure 5."
    )
    primary: Literal["welch", "paired"] = Field(
        default="welch",
        description="Each comparison's primary test on the agents' R_T: welch, or paired "
        "(the paired t-test over seeds, where every agent has a baseline agent of its seed).",
    )


class ReportFile(BaseModel):
    name: str
    kind: str = Field(description="report (Markdown), figure (PNG, SVG, PDF) or table (CSV).")
    url: str


class ReportMethod(BaseModel):
    method: str
    name: str
    agents: int
    episodes: int
    R_T: float = Field(description="Total collected reward of the method's average curve.")
    improvement_pct: float | None = Field(
        description="Over the baseline, in percent; None without one, or where the baseline's "
        "R_T is not positive (a percentage of it would mislead: see `difference`)."
    )
    difference: float | None = Field(
        default=None, description="R_T minus the baseline's, in points; None without one."
    )


class ReportPublic(BaseModel):
    study_id: int
    created_at: datetime
    sessions: list[int]
    baseline: str | None
    n_episodes: int
    notes: list[str] = Field(description="What the report left out or chose, and why.")
    methods: list[ReportMethod]
    files: list[ReportFile]
    report_url: str = Field(description="report.md, which links its figures and tables.")
    zip_url: str = Field(description="Every file in one zip.")
