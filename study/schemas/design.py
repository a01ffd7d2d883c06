"""An online study's design: its conditions, targets, capacity, panel setting, check,
questionnaire and outcome codes (`../shared/SPEC.md` section 5). Stored whole, defaults
written out, in `studies.design`."""

from __future__ import annotations

import re
import secrets
from collections.abc import Mapping
from typing import Annotated, Any, Literal, get_args
from urllib.parse import quote

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    GetJsonSchemaHandler,
    StringConstraints,
    model_validator,
)
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import core_schema

from analysis.preregistration import MEASURES, Preregistered, problem
from study.schemas.runs import given
from study.schemas.sessions import run_model
from study.schemas.types import KEY_NAMES, NO_NUL, Int, Key, Number, Text, Texts, plain_text
from study.schemas.visit import CheckSpec, QuestionnaireSpec

PANEL_PARAMS: dict[str, tuple[str, ...]] = {
    "prolific": ("PROLIFIC_PID", "STUDY_ID", "SESSION_ID"),
    "mturk": ("workerId", "assignmentId", "hitId", "turkSubmitTo"),
}
"""The URL parameters each panel sends; the first names the person (their panel id)."""
PROLIFIC_COMPLETE = "https://app.prolific.com/submissions/complete?cc={code}"
"""Where a Prolific participant returns to, with their code."""
MTURK_SUBMIT = "{turkSubmitTo}/mturk/externalSubmit?assignmentId={assignmentId}&code={code}"
"""Where an MTurk worker's HIT is submitted (an ExternalQuestion's form target)."""
MTURK_HOSTS = ("https://www.mturk.com", "https://workersandbox.mturk.com")
"""The `turkSubmitTo` values believed: the parameter comes with the link, so anything else
would make the study an open redirect."""
OutcomeName = Literal["completed", "declined", "excluded", "timed_out", "full"]
"""`study.db.models.Outcome`'s values, each with its own code and return URL."""
OUTCOMES: tuple[OutcomeName, ...] = get_args(OutcomeName)
ParamName = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$")]
URL_START = r"^(https?://|\{turkSubmitTo\}/)"
Url = Annotated[
    str,
    StringConstraints(max_length=2000, pattern=URL_START),
    AfterValidator(plain_text),
    Field(json_schema_extra={"pattern": URL_START + NO_NUL[1:]}),  # the whole text, no NUL
]
"""A return URL: `{code}` is the outcome's code, `{NAME}` the arrival's panel parameter NAME
(URL-encoded); `{turkSubmitTo}` may start it (MTurk's own hosts only)."""


def _human_run(value: Any) -> dict[str, Any]:
    """A condition's run read as a session's `run` is (`Run`: the same checks and 422s),
    kept as the fields given; its method is human unless it says so, and a null version is
    the current one."""
    run = given(run_model().model_validate(value))
    run.setdefault("method", "human")
    if run.get("version", 0) is None:
        del run["version"]
    return run


class _RunSchema:
    """The JSON Schema of a condition's run: the `Run` component, its method human."""

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        run_schema = run_model().__pydantic_core_schema__
        generator = getattr(handler, "generate_json_schema", None)  # a $ref to `Run`, not a copy
        run = generator.generate_inner(run_schema) if generator else handler(run_schema)
        human = {"properties": {"method": {"enum": ["human"], "default": "human"}}}
        return {"allOf": [run, human]}


HumanRun = Annotated[dict[str, Any], BeforeValidator(_human_run), _RunSchema()]
"""A condition's run (`_human_run`); its JSON Schema refers to the session body's `Run`."""


class Condition(BaseModel):
    """One arm of the study: the run each of its sessions gets (the body's `run` of
    `POST /api/studies/ID/sessions`, a human run for people), and its page texts (over the
    study's own)."""

    model_config = ConfigDict(extra="forbid")

    run: HumanRun = Field(
        default_factory=lambda: {"method": "human"},
        description="The run of each of its sessions, as a session's `run` (learner.run."
        "RunSpec's fields; unset ones take their defaults), method human: people advise.",
    )
    texts: Texts = Field(default_factory=dict, max_length=32)
    target: Int = Field(default=10, ge=1, le=100_000)
    """Completed participants wanted in this condition."""


def _code() -> str:
    return secrets.token_hex(4).upper()


class Panel(BaseModel):
    """Where participants come from: which URL parameters carry their ids, and where each
    outcome sends them back (a `{code}` in a URL is replaced by the outcome's code)."""

    model_config = ConfigDict(extra="forbid")

    kind: Literal["prolific", "mturk", "custom"] = "prolific"
    params: list[ParamName] = Field(default_factory=list, max_length=16)
    """The URL parameters kept (the first is the person's panel id); default: the panel's."""
    codes: dict[OutcomeName, Annotated[Text, Field(min_length=1, max_length=64)]] = Field(
        default_factory=dict
    )
    """A code per outcome; random ones are made for those not given."""
    urls: dict[OutcomeName, Url] = Field(default_factory=dict)
    """The return URL per outcome; Prolific's completion URL by default on Prolific."""
    return_delay_s: Int = Field(default=5, ge=0, le=600)
    """Seconds the outcome page shows the code before it sends the participant back."""

    @model_validator(mode="after")
    def _defaults(self) -> Panel:
        if not self.params:
            if self.kind == "custom":
                raise ValueError("a custom panel names its URL parameters in `params`")
            self.params = list(PANEL_PARAMS[self.kind])
        for outcome in OUTCOMES:
            self.codes.setdefault(outcome, _code())
            default = {"prolific": PROLIFIC_COMPLETE, "mturk": MTURK_SUBMIT}.get(self.kind)
            if default is not None:
                self.urls.setdefault(outcome, default)
        return self


class Primary(BaseModel):
    """The primary measure and test, fixed before the data (pre-registration): the report
    leads with it, marks every other test exploratory, and states the power the study had
    for its observed spread (`analysis.primary`)."""

    model_config = ConfigDict(extra="forbid")

    measure: Literal[tuple(MEASURES)]  # type: ignore[valid-type]
    """One of `analysis.preregistration.MEASURES`."""
    test: Literal["welch", "mann_whitney", "fisher"]
    """A test that fits the measure: welch or mann_whitney for a continuous one, fisher for
    a rate."""
    conditions: tuple[Key, Key] | None = None
    """The two conditions compared (the effect is the first's minus the second's); may be
    left out in a design of exactly two conditions."""
    effect: Number | None = Field(default=None, gt=0)
    """The smallest difference worth detecting, in the measure's units (the power stated
    is for it; without it, the report states the difference detectable at 80 %)."""

    @model_validator(mode="after")
    def _fits(self) -> Primary:
        why = problem(self.measure, self.test)
        if why is not None:
            raise ValueError(why)
        if self.conditions is not None and self.conditions[0] == self.conditions[1]:
            raise ValueError("primary.conditions must name two different conditions")
        return self


class StudyDesign(BaseModel):
    """Stored with every default written out (`model_dump()` of the validated design), so
    what a study does never changes when a default in this file does."""

    model_config = ConfigDict(extra="forbid")

    conditions: dict[Key, Condition] = Field(
        min_length=1, max_length=32, json_schema_extra={"propertyNames": KEY_NAMES}
    )
    capacity: Int = Field(default=8, ge=1, le=10_000)
    """Participants at once (started visits not ended); more arrivals see the study full.
    The default is what this project's 2-core machine holds with the advice round trip's
    p95 under 100 ms (8: 58 ms; 14: 741 ms; `benchmarks/bench_capacity.py`,
    docs/speed.md), measured with the benchmark's two Chromium pages on the same two cores. 30 at
    once reach the aim only with a pool practised for them (`pool`; the practice of arrivals
    beyond it shares the cores): then a median 99 ms (43-126) over five runs with the
    browsers, 23 ms without them (AVX2-only EPYC): measure yours and set it."""
    alpha: Number = Field(default=0.05, gt=0, lt=1)
    """The report's significance level for comparing the conditions."""
    idle_limit_s: Number = Field(default=600.0, gt=0, le=86_400)
    """Seconds without an answer before a visit ends as `timed_out` (final)."""
    pool: Int = Field(default=2, ge=0, le=100)
    """Sessions per condition kept made and pretrained ahead of arrivals (their seeds and
    conditions fixed when made), so an arrival's first turn does not wait for the robot's
    random practice; 0: each arrival's session practises when its link opens. The server
    caps all pools together (`IDEEPRL_POOL_LIMIT`)."""
    panel: Panel = Field(default_factory=Panel)
    check: CheckSpec | None = Field(default_factory=CheckSpec.default)
    questionnaire: QuestionnaireSpec | None = Field(default_factory=QuestionnaireSpec.default)
    primary: Primary | None = None
    """The pre-registered primary measure and test (None: every test is as the report
    makes it, none primary)."""

    @model_validator(mode="after")
    def _primary_conditions(self) -> StudyDesign:
        if self.primary is None:
            return self
        if self.primary.conditions is None:
            if len(self.conditions) != 2:
                raise ValueError(
                    "primary.conditions: name the two conditions the primary test compares "
                    f"(the design has {len(self.conditions)})"
                )
        else:
            unknown = [c for c in self.primary.conditions if c not in self.conditions]
            if unknown:
                raise ValueError(
                    f"primary.conditions: {unknown[0]!r} is not one of the design's conditions "
                    f"({', '.join(self.conditions)})"
                )
        return self

    def preregistered(self) -> Preregistered | None:
        """The primary test as the report reads it (None: the design fixed none)."""
        if self.primary is None:
            return None
        a, b = self.primary.conditions or tuple(self.conditions)
        return Preregistered(self.primary.measure, self.primary.test, (a, b), self.primary.effect)

    def code(self, outcome: str) -> str:
        return self.panel.codes[outcome]  # type: ignore[index]

    def return_url(self, outcome: str, params: Mapping[str, str] | None = None) -> str | None:
        """The panel URL this outcome sends the participant to: its code and the arrival's
        panel parameters filled in (a missing one empty; `turkSubmitTo` only MTurk's)."""
        url = self.panel.urls.get(outcome)  # type: ignore[call-overload]
        if url is None:
            return None
        given = dict(params or {})
        if given.get("turkSubmitTo", "").rstrip("/") not in MTURK_HOSTS:
            given["turkSubmitTo"] = MTURK_HOSTS[0]
        submit = given.pop("turkSubmitTo").rstrip("/")
        url = url.replace("{turkSubmitTo}", submit, 1) if url.startswith("{") else url
        values = {"code": self.code(outcome), **given}
        return re.sub(r"\{([A-Za-z0-9_.-]+)\}", lambda m: quote(values.get(m[1], ""), safe=""), url)


CODE = re.compile(r"[A-Za-z0-9_.-]+")
"""An outcome's code as a new design may give it: what a participant copies into the panel,
so letters, digits, `_`, `.` and `-` only (as Prolific's and MTurk's codes are)."""


def _copyable_codes(design: StudyDesign) -> StudyDesign:
    for outcome, code in design.panel.codes.items():
        if not CODE.fullmatch(code):
            raise ValueError(
                f"panel.codes.{outcome}: {code[:64]!r} is not a code a participant can copy "
                "into the panel; use letters, digits, _ . and - only"
            )
    return design


NewStudyDesign = Annotated[StudyDesign, AfterValidator(_copyable_codes)]
"""A design as a request gives it: its codes checked as well. Designs stored before the
check are read as `StudyDesign`, so a study under way is never refused its own design."""
