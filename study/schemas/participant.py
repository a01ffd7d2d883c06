"""Bodies of the participant endpoints (the advising page of a human session)."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool

from sim.actions import ACTION_NAMES
from study.schemas.types import KEY_NAMES, NO_NUL, Int, Key, Number, Text
from study.schemas.visit import Section

MAX_DECISION_TIME_S = 86_400.0
"""A decision time beyond a day is a broken clock, not a decision."""


class AdviceCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    advice_index: Int = Field(ge=0, le=2**31 - 1, description="Index of the advice (0-based).")
    action: Int = Field(
        ge=0,
        le=31,
        description="The action's index in the task's actions (the state's action_names; the "
        "sorting robot's: 0 grab, 1 move right, 2 move left, 3 drop).",
    )
    decision_time_s: Number | None = Field(
        default=None,
        ge=0.0,
        le=MAX_DECISION_TIME_S,
        allow_inf_nan=False,
        description="Seconds from the moment the page's buttons became active to the click or "
        "key, on the browser's monotonic clock (performance.now()); stored beside the "
        "server's response_time_s, which also counts the 3-D replay and the network.",
    )


class HistoryItem(BaseModel):
    advice_index: int
    action: int
    action_name: str
    reward: float | None = None


class HeldObject(BaseModel):
    shape: str
    color: str


class ParticipantState(BaseModel):
    """Everything the advising page shows; `version` grows with every change (long-poll)."""

    session_id: int
    status: str = Field(
        description="As the researcher's API shows it: created, running, queued (the "
        "advice is over and the learner waits for a trainer slot), paused, finished, "
        "stopped, interrupted, abandoned, failed, declined, excluded or timed_out."
    )
    message: str = ""
    version: int
    advice_wanted: bool
    advice_index: int | None = None
    observation_png: str | None = Field(
        default=None, description="Base64 PNG (64x64, lossless) of what the learner sees."
    )
    robot_moving: bool
    held: HeldObject | None = Field(
        default=None, description="What the robot holds at this request (None: nothing)."
    )
    station: str | None = Field(
        default=None, description="Where the arm is at this request: center, left, right."
    )
    own_moves: int | None = Field(
        default=None,
        description="Actions the robot took on its own since the last advised one (the "
        "alternating strategy's moves between turns); None before the first choice.",
    )
    advice_budget: int
    advice_given: int
    advice_left: int
    last_reward: float | None = None
    episode: int = 0
    stage: str | None = None
    ready: bool = Field(
        default=False, description="Consent and induction done: advice may be asked."
    )
    queued: bool = Field(
        default=False,
        description="Advice over; the learner waits for a free trainer slot (status queued).",
    )
    queue_place: int | None = Field(
        default=None,
        description="While queued: 1 for the session next in line for a trainer slot, 2 for "
        "the one after, ...; null otherwise.",
    )
    history: list[HistoryItem] = Field(default_factory=list)
    action_names: list[str] = Field(
        default_factory=lambda: list(ACTION_NAMES),
        description="The task's actions in order, as the buttons name them.",
    )
    frame_png: str | None = Field(
        default=None,
        description="A task without a live 3-D view: what people see at this request, PNG "
        "in base64 (None for the sorting robot, whose scene the 3-D view shows).",
    )
    rated_action: int | None = Field(
        default=None,
        description="Evaluative feedback: the turn asks for a rating of this action, which "
        "the learner took (POST /api/participant/rating); None: the turn asks for advice.",
    )
    rated_reward: float | None = Field(
        default=None, description="Evaluative feedback: the reward the rated action earned."
    )
    rating_time_out_s: float | None = Field(
        default=None,
        description="Evaluative feedback: seconds the learner waits for the rating, from "
        "when it asked; after them it goes on with no answer.",
    )
    rating_left_s: float | None = Field(
        default=None, description="Evaluative feedback: seconds left to rate, now."
    )


class AdviceReceipt(BaseModel):
    advice_index: int
    action: int
    duplicate: bool = Field(description="True if this advice had been received already.")
    response_time_s: float
    version: int = Field(description="State version after this advice: long-poll after it.")
    state: ParticipantState | None = Field(
        default=None, description="With ?wait=S: the state after what happened next."
    )


class RatingCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    advice_index: Int = Field(
        ge=0, le=2**31 - 1, description="Index of the turn rated (the state's advice_index)."
    )
    rating: Literal["good", "bad"] = Field(description="The participant's rating of the action.")
    decision_time_s: Number | None = Field(
        default=None,
        ge=0.0,
        le=MAX_DECISION_TIME_S,
        allow_inf_nan=False,
        description="Seconds from the moment the page asked for the rating to the click or "
        "key, on the browser's monotonic clock (performance.now()).",
    )


class RatingReceipt(BaseModel):
    advice_index: int
    action: int = Field(description="The action rated.")
    judgement: float | None = Field(description="+1 good, -1 bad (None: no answer).")
    shaping: float = Field(description="What the rating added to the learner's reward.")
    duplicate: bool = Field(description="True if this rating had been received already.")
    response_time_s: float = Field(description="The server's time from showing to receiving.")
    version: int
    state: ParticipantState | None = Field(
        default=None, description="With ?wait=S: the state after what happened next."
    )


class ConsentCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    agree: StrictBool = Field(description="True: consent; False: decline (JSON true or false).")
    texts_version: int | None = Field(
        default=None,
        ge=1,
        le=2**31 - 1,
        description="Id of the texts version shown (GET /api/participant/consent); default: "
        "the texts as shown now.",
    )


class ConsentState(BaseModel):
    """What the participant read and decided, as the server recorded it."""

    texts_version: int = Field(description="Id of the texts version shown now or consented to.")
    texts: dict[str, str] = Field(description="The texts of that version, exactly as shown.")
    consented_at: datetime | None = None
    declined_at: datetime | None = None
    induction_done_at: datetime | None = None


class Readiness(BaseModel):
    """How far the robot's random pretraining is before the first turn (the page polls)."""

    status: str = Field(description="As in the participant's state (queued included).")
    steps_done: int = Field(description="Environment steps taken so far.")
    steps_before_first_turn: int = Field(description="Random steps before the first advice.")
    ready: bool = Field(description="The robot waits for (or already asks) the first advice.")


class CheckChoice(BaseModel):
    value: str
    label: str


class CheckQuestionShown(BaseModel):
    """A comprehension check question as the participant sees it (never its answer)."""

    id: str
    text: str
    choices: list[CheckChoice]


class CheckState(BaseModel):
    """The comprehension check of an online study, and how far this participant is."""

    required: bool = Field(description="The study asks the check before the advice starts.")
    questions: list[CheckQuestionShown] = Field(default_factory=list)
    tries: int = Field(default=0, description="Tries allowed.")
    tries_used: int = 0
    passed: bool = False
    excluded: bool = Field(default=False, description="Every try failed: the visit has ended.")


class CheckCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    answers: dict[Key, Annotated[Key, Field(json_schema_extra={"pattern": NO_NUL})]] = Field(
        max_length=50,
        description="{question id: chosen value}, one for every question.",
        json_schema_extra={"propertyNames": KEY_NAMES},
    )


class CheckResult(CheckState):
    correct: bool = Field(description="Every answer of this try was right.")
    wrong: list[str] = Field(
        default_factory=list, description="Ids of the questions answered wrong (not the answers)."
    )


Answer = Int | Number | Annotated[Text, Field(max_length=5000)] | None
"""One item's answer; an item's own `max_length` (at most 5000) is checked against it."""


class QuestionnaireCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    answers: dict[
        Key, Annotated[dict[Key, Answer], Field(json_schema_extra={"propertyNames": KEY_NAMES})]
    ] = Field(
        max_length=20,
        json_schema_extra={"propertyNames": KEY_NAMES},
        description="{instrument: {item id: answer}}: a Likert point (1..points), a number, a "
        'choice or text, or "Prefer not to say" where offered; leave an optional item out '
        "(or null) to skip it.",
    )


class QuestionnaireState(BaseModel):
    """The questionnaire of an online study (the sections with their items, as the design
    has them) and whether this participant submitted it."""

    required: bool = Field(description="The study asks a questionnaire after the advice.")
    sections: list[Section] = Field(default_factory=list)
    available: bool = Field(default=False, description="The advice is done: it may be answered.")
    submitted_at: datetime | None = None


# --- what the participant's pages read beside it (`server.routes.viewing`) ---------------
class Playback(BaseModel):
    remaining_s: float = Field(description="Seconds until the 3-D view has shown the last move.")
    viewers: int = Field(description="Open 3-D views of this session.")
    scene_shown: bool = Field(
        default=False, description="A 3-D view of this session has drawn the robot's scene."
    )


class CurvePoint(BaseModel):
    episode: int
    collected_reward: float


class LearningCurve(BaseModel):
    status: str = Field(
        description="As in the participant's state: queued while the learner waits for a "
        "trainer slot, running while it trains, then finished (or how it ended)."
    )
    queued: bool = Field(
        default=False,
        description="Waiting in the server's queue for a free trainer slot (status queued).",
    )
    queue_place: int | None = Field(
        default=None,
        description="While queued: 1 for the session next in line for a trainer slot, 2 for "
        "the one after, ...",
    )
    wait_s: float | None = Field(
        default=None,
        description="While queued: the estimated seconds until it starts training, from how "
        "fast the sessions in the slots train now (null until one has finished an episode).",
    )
    episodes: int = Field(description="Training episodes the session will run.")
    curve: list[CurvePoint] = Field(description="Collected reward per finished episode.")
