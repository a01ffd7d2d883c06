"""What an online study asks around the advice: the comprehension check after the
induction and the questionnaire after it (`../shared/SPEC.md` section 5 gives the defaults).

Contract between the design (`study.schemas.design`) and the visit pages: the design
holds one `CheckSpec | None` and one `QuestionnaireSpec | None`; `CheckSpec.default()` and
`QuestionnaireSpec.default()` are the SPEC's defaults. Torch-free: the analysis scores the
answers with the same definitions (`study.schemas.instruments`).
"""

from __future__ import annotations

from typing import Annotated, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, StringConstraints, model_validator

from sim.rules import COLORS, OBJECTS, SHAPES
from study.schemas import instruments as inst
from study.schemas.types import Number, Text

Id = Annotated[str, StringConstraints(pattern=r"^[a-z][a-z0-9_]{0,39}$")]
"""A question's or item's id: lowercase letters, digits and _, starting with a letter."""
Label = Annotated[Text, StringConstraints(min_length=1, max_length=500)]
SideOf = Annotated[Text, Field(json_schema_extra={"pattern": f"^({'|'.join(OBJECTS)})$"})]
"""An object as `shape/color` (its check and message are `CheckQuestion`'s)."""
SIDE_CHOICES = ("left", "right")


class Choice(BaseModel):
    model_config = ConfigDict(extra="forbid")

    value: Id = Field(description="What the answer stores (e.g. `left`).")
    label: Label = Field(description="What the participant reads.")


def _unique(values: list[str], what: str) -> None:
    seen = {v for v in values if values.count(v) > 1}
    if seen:
        raise ValueError(f"{what} must be unique; {', '.join(sorted(seen))} appears twice")


class CheckQuestion(BaseModel):
    """One multiple-choice question; its right answer is either fixed (`answer`) or the
    side table of an object under the session's own sort rule (`side_of`), computed when
    the participant answers, so one check serves conditions with different rules."""

    model_config = ConfigDict(extra="forbid")

    id: Id
    text: Label
    choices: list[Choice] = Field(min_length=2, max_length=8)
    answer: Id | None = Field(default=None, description="The value of the right choice.")
    side_of: SideOf | None = Field(
        default=None,
        description='An object "shape/color" (e.g. "cube/blue"): the right answer is its '
        "side under the session's sort rule; the choices then hold `left` and `right`.",
    )

    @model_validator(mode="after")
    def _one_answer(self) -> Self:
        values = [c.value for c in self.choices]
        _unique(values, f"question {self.id}: choice values")
        if (self.answer is None) == (self.side_of is None):
            raise ValueError(f"question {self.id}: give either `answer` or `side_of`, not both")
        if self.answer is not None and self.answer not in values:
            raise ValueError(f"question {self.id}: answer {self.answer!r} is not a choice value")
        if self.side_of is not None:
            shape, _, color = self.side_of.partition("/")
            if shape not in SHAPES or color not in COLORS:
                raise ValueError(
                    f"question {self.id}: side_of {self.side_of!r} is not an object "
                    f"shape/color (shapes {', '.join(SHAPES)}; colors {', '.join(COLORS)})"
                )
            if not set(SIDE_CHOICES) <= set(values):
                raise ValueError(
                    f"question {self.id}: with side_of, the choices need the values left and right"
                )
        return self


def default_questions() -> list[CheckQuestion]:
    """SPEC 5: where a blue cube goes, where a red disk (under the session's sort rule),
    and what Drop does over the center table (nothing: the arm keeps its position)."""
    sides = [
        Choice(value="left", label="On the left table"),
        Choice(value="right", label="On the right table"),
        Choice(value="centre", label="It stays on the center table"),
    ]
    where = "Under the sorting rule of this study, where does a {} go?"
    return [
        CheckQuestion(
            id="blue_cube", text=where.format("blue cube"), choices=sides, side_of="cube/blue"
        ),
        CheckQuestion(
            id="red_disk", text=where.format("red disk"), choices=sides, side_of="disk/red"
        ),
        CheckQuestion(
            id="drop_at_centre",
            text="The robot holds an object and its arm is over the center table. "
            "What does Drop do?",
            choices=[
                Choice(value="release", label="It puts the object back on the center table"),
                Choice(value="keep", label="Nothing: the robot keeps holding it where it is"),
                Choice(value="right", label="It carries the object to the right table"),
            ],
            answer="keep",
        ),
    ]


class CheckSpec(BaseModel):
    """The comprehension check: questions with correct answers and a number of tries;
    failing every try ends the visit as `excluded`."""

    model_config = ConfigDict(extra="forbid")

    tries: int = Field(default=2, ge=1, le=10)
    questions: list[CheckQuestion] = Field(
        default_factory=default_questions, min_length=1, max_length=20
    )

    @model_validator(mode="after")
    def _unique_ids(self) -> Self:
        _unique([q.id for q in self.questions], "check question ids")
        return self

    @classmethod
    def default(cls) -> CheckSpec:
        """The SPEC's default check (the session's sort rule decides the right answers)."""
        return cls()


Kind = Literal["likert", "choice", "number", "text"]
SHAPE_FIELDS = ("points", "anchors", "choices", "minimum", "maximum", "step", "max_length")
NEEDS: dict[str, set[str]] = {
    "likert": {"points", "anchors"},
    "choice": {"choices"},
    "number": {"minimum", "maximum"},
    "text": set(),
}
MAY: dict[str, set[str]] = {
    "likert": set(),
    "choice": set(),
    "number": {"step", "anchors"},
    "text": {"max_length"},
}
"""Which of `SHAPE_FIELDS` an item of each kind needs, and which it may have besides."""


class Item(BaseModel):
    """One questionnaire item. `likert`: `points` (2-11) with `anchors` (the two ends, or
    one per point), answered 1..points; `choice`: one of `choices`; `number`: between
    `minimum` and `maximum` in steps of `step` (a slider when `anchors` name its ends);
    `text`: free text up to `max_length`. `prefer_not_to_say` offers that answer too."""

    model_config = ConfigDict(extra="forbid")

    id: Id
    kind: Kind
    text: Label
    required: bool = False
    points: int | None = Field(default=None, ge=2, le=11)
    anchors: list[Label] | None = None
    choices: list[Label] | None = Field(default=None, min_length=2, max_length=20)
    minimum: Number | None = None
    maximum: Number | None = None
    step: Number | None = Field(default=None, gt=0)
    max_length: int | None = Field(default=None, ge=1, le=5000)
    prefer_not_to_say: bool = False

    @model_validator(mode="after")
    def _fits_kind(self) -> Self:
        needs, allowed = NEEDS[self.kind], NEEDS[self.kind] | MAY[self.kind]
        for name in SHAPE_FIELDS:
            given = getattr(self, name) is not None
            if name in needs and not given:
                raise ValueError(f"item {self.id}: a {self.kind} item needs `{name}`")
            if given and name not in allowed:
                raise ValueError(f"item {self.id}: a {self.kind} item takes no `{name}`")
        if self.kind == "likert":
            assert self.points is not None and self.anchors is not None
            if len(self.anchors) not in (2, self.points):
                raise ValueError(
                    f"item {self.id}: anchors name the two ends or each of the {self.points} "
                    f"points, not {len(self.anchors)}"
                )
        if self.kind == "number":
            assert self.minimum is not None and self.maximum is not None
            if self.minimum >= self.maximum:
                raise ValueError(f"item {self.id}: minimum must be below maximum")
            if self.anchors is not None and len(self.anchors) != 2:
                raise ValueError(f"item {self.id}: a number's anchors name its two ends")
        if self.choices is not None:
            _unique(list(self.choices), f"item {self.id}: choices")
        return self


class Section(BaseModel):
    """Items asked together under one heading, stored under one instrument name."""

    instrument: str
    title: str
    intro: str
    items: list[Item]


class QuestionnaireSpec(BaseModel):
    """The questionnaire after the advice: the built-in instruments the design keeps, then
    the researcher's own `items` (stored as instrument `custom`)."""

    model_config = ConfigDict(extra="forbid")

    nasa_tlx: bool = Field(default=True, description="NASA-TLX raw (six subscales, 0-100).")
    trust: bool = Field(
        default=True, description="Trust checklist (Jian, Bisantz and Drury 2000; 12 items, 1-7)."
    )
    demographics: bool = Field(
        default=True, description="Age band, gender, experience with robots and AI (optional)."
    )
    items: list[Item] = Field(default_factory=list, max_length=100)

    @model_validator(mode="after")
    def _something_to_ask(self) -> Self:
        _unique([i.id for i in self.items], "questionnaire item ids")
        if not (self.nasa_tlx or self.trust or self.demographics or self.items):
            raise ValueError(
                "the questionnaire asks nothing; keep a built-in, add items, or set the "
                "design's questionnaire to null"
            )
        return self

    @classmethod
    def default(cls) -> QuestionnaireSpec:
        """The SPEC's default: NASA-TLX raw, the trust checklist, optional demographics."""
        return cls()

    def sections(self, agent: str = "robot", feedback: str = "advice") -> list[Section]:
        """What the page asks, in order; its words for the session's kind of feedback
        (advice, or ratings of the agent's moves: evaluative)."""
        out = []
        if self.nasa_tlx:
            out.append(_nasa_tlx(feedback))
        if self.trust:
            out.append(_trust(agent, feedback))
        if self.items:
            out.append(
                Section(
                    instrument="custom",
                    title="A few more questions",
                    intro="",
                    items=list(self.items),
                )
            )
        if self.demographics:
            out.append(_demographics())
        return out


GAVE = {"advice": "the advice you just gave", "evaluative": "the ratings you just gave"}
"""What the participant did, by the run's kind of feedback, in the questionnaire's words."""
DID = {"advice": "advised", "evaluative": "rated"}


def _nasa_tlx(feedback: str = "advice") -> Section:
    items = [
        Item(
            id=s.id,
            kind="number",
            text=f"{s.title}: {s.question}",
            required=True,
            minimum=inst.TLX_MIN,
            maximum=inst.TLX_MAX,
            step=inst.TLX_STEP,
            anchors=[s.low, s.high],
        )
        for s in inst.NASA_TLX
    ]
    intro = f"About {GAVE[feedback]}: move each slider to where it fits best."
    return Section(instrument="nasa_tlx", title="Workload", intro=intro, items=items)


def _trust(agent: str = "robot", feedback: str = "advice") -> Section:
    """The trust checklist about what the participant advised: the sorting robot, or the
    task's own agent (`tasks.Task.agent`), its items' words taken from it."""
    items = [
        Item(
            id=inst.trust_item_id(n),
            kind="likert",
            text=text.replace("robot", agent),
            required=True,
            points=inst.TRUST_POINTS,
            anchors=list(inst.TRUST_ANCHORS),
        )
        for n, text in enumerate(inst.TRUST_ITEMS, start=1)
    ]
    intro = f"How much does each statement fit your impression of the {agent} you {DID[feedback]}?"
    return Section(instrument="trust", title=f"The {agent}", intro=intro, items=items)


def _demographics() -> Section:
    items = [
        Item(
            id=id_,
            kind="choice" if choices else "text",
            text=text,
            choices=list(choices) if choices else None,
            max_length=None if choices else 100,
            prefer_not_to_say=True,
        )
        for id_, text, choices in inst.DEMOGRAPHICS
    ]
    intro = "Every question here is optional."
    return Section(instrument="demographics", title="About you", intro=intro, items=items)
