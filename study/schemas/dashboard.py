"""Bodies of the researchers' dashboard (`server.routes.dashboard`): what its page polls
and sends. Not in the OpenAPI document: the dashboard's routes are the page's own."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field

from analysis.baseline import AUTO
from study.schemas.design import NewStudyDesign
from study.schemas.studies import ConditionCounts
from study.schemas.types import Text


class SessionRow(BaseModel):
    id: int
    label: str
    method: str
    seed: int
    participant: str | None
    participant_url: str | None
    status: str
    status_detail: str
    progress: dict[str, Any]
    declined: bool = False
    condition: str | None = None
    outcome: str | None = None
    preview: bool = False
    pooled: bool = False
    node: str | None = None
    """Where it trains, or last trained: this machine, or a node of the Ray cluster
    (`worker_host`); None before it starts."""


class StudyRow(BaseModel):
    id: int
    name: str
    description: str
    sessions: list[SessionRow]
    design: dict[str, Any] | None = None
    join_url: str | None = None
    conditions: list[ConditionCounts] = Field(default_factory=list)
    """An online study's per-condition counts (`GET /api/studies/ID/conditions`)."""
    report_built_at: str | None = None
    """When its published report was built; None without one (never built, or removed with
    a deleted session): the page shows, refetches or hides its report by it."""


class NewDesign(BaseModel):
    design: NewStudyDesign


class NewStudy(BaseModel):
    name: Text = Field(min_length=1, max_length=200)


class NewParticipant(BaseModel):
    participant: Text | None = Field(default=None, max_length=64)
    """Pseudonym; generated when empty."""
    pretrain: bool | None = None
    """Start the session's random pretraining now (as `?pretrain=true` of the REST API), so
    the robot is ready when the participant's induction ends; false: it starts when the
    participant opens the link; unset: the server's `pretrain_on_create` (on)."""


class DashboardReport(BaseModel):
    n_episodes: int | None = Field(default=None, ge=1, le=100_000)
    """First N episodes of every session; default: the length they have in common."""
    baseline: Text = Field(default=AUTO, max_length=40)
    """auto (autonomous when present), none, or a method (an online study: a condition),
    as the REST API's report takes it."""
