"""Bodies of the sessions resource: what a researcher sets, and what they read back."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from datetime import datetime
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, create_model, model_validator

from learner.fields import bounded, checked, leaves
from learner.run import SPEC_VERSION, RunSpec, declared
from study.schemas.runs import body_model, leaf_schema, leaf_type
from study.schemas.types import WHOLE

API_VERSION_NOTE = (
    "Since API version 2.0 a session's run is one object, `run` (every field of "
    "learner.run.RunSpec), beside the session's own fields: "
    '{"run": {"method": "human", "seed": 3, "preset": "paper", "config": {"episodes": 300}, '
    '"strategy": "early", "scenario": {"reward_scheme": "paper"}}, "label": "pilot", '
    '"participant": "P01"}. See docs/api.md.'
)


@dataclass(frozen=True)
@checked()
class SessionOptions:
    """What describes a session but not its run: its name, its participant, how its worker
    treats it. Declared like the run (`learner.fields`), beside it in the REST body."""

    label: str = bounded("", max_length=200)
    """Free text, e.g. a batch name."""
    participant: str | None = bounded(None, max_length=64, pattern=r"[A-Za-z0-9_-]+")
    """Pseudonym of the participant (human sessions); generated when omitted."""
    keep_replay_memory: bool | None = bounded(None)
    """Keep the replay memory in the final checkpoint (default: the server's
    keep_replay_memory setting). Without it the final checkpoint holds the network and what
    an advisor needs, a few MB instead of about 250 MB at paper scale."""
    idle_limit_s: float | None = bounded(None, 0.0, 86_400.0, exclusive_minimum=True)
    """Seconds without advice before a human session is abandoned (default: the server's)."""


NOT_THE_RUN = tuple(f.name for f in dataclasses.fields(SessionOptions))


def _flat_body(data: Any) -> Any:
    """The body of API 1.x (the run's fields loose at the top) gets a 422 showing the new
    shape, rather than a list of unknown fields."""
    if isinstance(data, dict) and "run" not in data and set(data) - set(NOT_THE_RUN):
        raise ValueError(API_VERSION_NOTE)
    return data


_CREATE_MODELS: dict[type, type[BaseModel]] = {}


def session_create_model() -> type[BaseModel]:
    """The REST body that creates a session: `run` (the run, the tree of its declaration,
    `learner.run.declared`) beside the session's own options (`SessionOptions`); one model
    per declaration (a dict, not `functools.cache`, whose arguments mypy wants `Hashable`: a
    dataclass type is not)."""
    declaration = declared()
    if declaration not in _CREATE_MODELS:
        _CREATE_MODELS[declaration] = _session_create_model(declaration)
    return _CREATE_MODELS[declaration]


def _session_create_model(declaration: type[RunSpec]) -> type[BaseModel]:
    options = body_model(SessionOptions, "SessionOptions")
    model = create_model(
        "SessionCreate",
        __base__=options,
        # pydantic's annotation wants plain functions; its docs pass decorated ones
        __validators__={"flat": model_validator(mode="before")(_flat_body)},  # type: ignore[dict-item]
        __doc__="A session: its run, described once, and the session's own options. Unset "
        "fields take their defaults (the learner config's: its preset's).",
        run=(
            _run_model(declaration),
            Field(
                description="The run (learner.run.RunSpec): method, seed, preset, config, "
                "strategy and its options, advisor, motion, sort rule, scenario."
            ),
        ),
    )
    return model


def _offered_method(declaration: type) -> Any:
    """`method` as the API takes it: every method but replayed, which only `ideeprl replay`
    makes (it gives the run a recorded session's advice stream)."""
    [leaf] = [leaf for leaf in leaves(declaration) if leaf.path == ("method",)]
    schema = leaf_schema(leaf)
    schema["enum"] = [m for m in schema["enum"] if m != "replayed"]
    return leaf_type(leaf, schema)


def _run_model(declaration: type) -> type[BaseModel]:
    """The run's body: every field of `declaration`, and the stored document's `version`
    (so a session's `run`, or an export's `run_spec`, is accepted back as it is)."""
    return create_model(
        "Run",
        __base__=body_model(declaration, "RunFields"),
        __doc__=(declaration.__doc__ or "").strip(),
        method=(_offered_method(declaration), Field(default=None)),
        version=(
            Annotated[int, Field(strict=True, ge=1, le=SPEC_VERSION), WHOLE] | None,
            Field(default=None, description=f"The document's version (1 to {SPEC_VERSION})."),
        ),
    )


def run_model() -> type[BaseModel]:
    """The body of a run (`Run`) under the declaration in force: a session's `run`, and
    each condition's of a study design."""
    run = session_create_model().model_fields["run"].annotation
    assert isinstance(run, type) and issubclass(run, BaseModel)
    return run


SessionCreate = session_create_model()


class SessionPublic(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    study_id: int
    label: str
    method: str = Field(description="The run's method (run.method), for lists.")
    seed: int = Field(description="The run's seed (run.seed), for lists.")
    run: dict[str, Any] = Field(
        description="The run as stored: learner.run.RunSpec's document (every field spelled "
        "out, numerics pinned), accepted back unchanged as a new session's `run`."
    )
    numerics_overrides: list[Any] = Field(
        default_factory=list,
        description="Resumes that overrode the run's pinned numerics, each recorded.",
    )
    provenance: list[Any] = Field(
        default_factory=list,
        description="Where the run was computed, one entry per start or resume: code version "
        "(a hash of sim/ and learner/), commit, CPU kind, torch and Python versions, numerics.",
    )
    idle_limit_s: float | None
    keep_replay_memory: bool | None = None
    participant: str | None = None
    participant_url: str | None = None
    status: str = Field(
        description="created, running, queued (a running session whose advice is over, "
        "waiting for a trainer slot), paused, finished, stopped, interrupted, abandoned, "
        "failed, declined, excluded or timed_out."
    )
    queue_place: int | None = Field(
        default=None,
        description="While queued: 1 for the sessions next to take a trainer slot, 2 for "
        "those after, ...; null otherwise.",
    )
    status_detail: str
    progress: dict[str, Any]
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    worker_pid: int | None
    checkpoint_step: int
    consented_at: datetime | None = Field(
        default=None, description="When the participant consented (human sessions)."
    )
    declined_at: datetime | None = Field(
        default=None, description="When the participant last declined (human sessions)."
    )
    induction_done_at: datetime | None = Field(
        default=None, description="When they finished the induction: advice may be asked."
    )
    texts_version: int | None = Field(
        default=None, description="Version of the study's texts the participant was shown."
    )
    condition: str | None = Field(
        default=None, description="The online study's condition it was assigned to."
    )
    pooled: bool = Field(
        default=False,
        description="Made ahead of arrivals, waiting pretrained in its condition's pool: "
        "nobody's yet, not counted, out of exports until an arrival takes it.",
    )
    preview: bool = Field(
        default=False, description="A researcher's preview: no place, out of exports."
    )
    outcome: str | None = Field(
        default=None,
        description="How the online visit ended: completed, declined, excluded, timed_out.",
    )
    replay_of: int | None = Field(
        default=None,
        description="A replay's source session in this database (method replayed: fed its "
        "advice by order; deleting the source deletes the replay), else null.",
    )


class SessionCreated(SessionPublic):
    participant_token: str | None = Field(
        default=None, description="The participant's secret; their link is participant_url."
    )


class Progress(BaseModel):
    """Live progress of a session (from its worker while it runs, else the last saved)."""

    session_id: int
    status: str
    stage: str | None = Field(
        default=None, description="pretrain or train: the stage of the run's next step."
    )
    global_step: int = 0
    episode: int = 0
    episodes: int = 0
    epsilon: float | None = None
    collected_reward: float = 0.0
    last_episode_reward: float | None = None
    advice_given: int = 0
    advice_budget: int = 0
    advice_left: int = 0
    advice_wanted: bool = False
    queued: bool = Field(
        default=False,
        description="Advice over; waiting in the server's queue for a free trainer slot "
        "(status queued).",
    )
    queue_place: int | None = Field(
        default=None,
        description="While queued: 1 for the sessions next to take a trainer slot, 2 for "
        "those after, ...; null otherwise.",
    )
    consented: bool = Field(default=False, description="The participant consented (human).")


class EpisodePublic(BaseModel):
    """One episode (the learner's `EpisodeRecord`); the column dictionary explains each."""

    model_config = ConfigDict(from_attributes=True)

    stage: str
    episode: int
    collected_reward: float
    steps: int
    placed_correct: int
    misplaced: int
    lost: int
    success: bool
    advised_steps: int
    epsilon: float
    mean_loss: float | None
    first_global_step: int
    last_global_step: int
    wall_time: float


class AdvicePublic(BaseModel):
    """One advice, without its image (GET .../advice/INDEX.png has it)."""

    model_config = ConfigDict(from_attributes=True)

    advice_index: int
    global_step: int
    advisor: str
    action: int | None = Field(
        description="The advised action; null only for a replay's request beyond its recorded "
        "stream (asked, counted against the budget, none given)."
    )
    greedy_action: int | None
    response_time_s: float
    decision_time_s: float | None = None
    requested_at: datetime
    answered_at: datetime
    same_observation: bool | None = Field(
        default=None,
        description="Replayed advice: whether it met the image its advisor saw; null for "
        "advice given live and for requests beyond the stream.",
    )
    correct_action: int | None = Field(
        default=None,
        description="The task's correct action at the advised step (the advice is accurate "
        "when action equals it, or is one of correct_actions); null where the task cannot say.",
    )
    correct_actions: list[int] | None = Field(
        default=None,
        description="Every action as right as correct_action there, it among them (the grid "
        "world's moves equally near the goal); null where the task cannot say, and for advice "
        "stored before it was recorded.",
    )
