"""The built-in questionnaires and how they are scored (`../shared/SPEC.md` section 5).

Plain data and plain functions (no pydantic, no torch), so the export and the analysis
score answers with the very definitions the pages asked them with.

- NASA-TLX, raw (Hart and Staveland 1988; "raw TLX": no pairwise weighting, Hart 2006):
  six subscales, each 0-100 in steps of 5; the score is their unweighted mean. Performance
  runs from "Perfect" (0) to "Failure" (100), so every subscale reads "higher = more load".
- Checklist for trust between people and automation (Jian, Bisantz and Drury 2000): twelve
  statements, 1 ("Not at all") to 7 ("Extremely"); the first five are the distrust items,
  reversed (8 - answer) before the mean. "The system" is said "the robot" here, the thing
  the participant advised.
- Demographics: age band, gender (free text), prior experience with robots and with AI;
  each optional, each with "Prefer not to say".
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

PREFER_NOT_TO_SAY = "Prefer not to say"


class Subscale(NamedTuple):
    id: str
    title: str
    question: str
    low: str
    high: str


NASA_TLX: tuple[Subscale, ...] = (
    Subscale(
        "mental", "Mental demand", "How mentally demanding was the task?", "Very low", "Very high"
    ),
    Subscale(
        "physical",
        "Physical demand",
        "How physically demanding was the task?",
        "Very low",
        "Very high",
    ),
    Subscale(
        "temporal",
        "Temporal demand",
        "How hurried or rushed was the pace of the task?",
        "Very low",
        "Very high",
    ),
    Subscale(
        "performance",
        "Performance",
        "How successful were you in accomplishing what you were asked to do?",
        "Perfect",
        "Failure",
    ),
    Subscale(
        "effort",
        "Effort",
        "How hard did you have to work to accomplish your level of performance?",
        "Very low",
        "Very high",
    ),
    Subscale(
        "frustration",
        "Frustration",
        "How insecure, discouraged, irritated, stressed, and annoyed were you?",
        "Very low",
        "Very high",
    ),
)
"""The six subscales in the instrument's order, with its own questions and anchors."""
TLX_MIN, TLX_MAX, TLX_STEP = 0, 100, 5

TRUST_ITEMS: tuple[str, ...] = (
    "The robot is deceptive.",
    "The robot behaves in an underhanded manner.",
    "I am suspicious of the robot's intent, action, or outputs.",
    "I am wary of the robot.",
    "The robot's actions will have a harmful or injurious outcome.",
    "I am confident in the robot.",
    "The robot provides security.",
    "The robot has integrity.",
    "The robot is dependable.",
    "The robot is reliable.",
    "I can trust the robot.",
    "I am familiar with the robot.",
)
TRUST_POINTS = 7
TRUST_ANCHORS = ("Not at all", "Extremely")
TRUST_REVERSED = frozenset({1, 2, 3, 4, 5})
"""The distrust items (1-based), scored 8 - answer."""


def trust_item_id(number: int) -> str:
    return f"item_{number:02d}"


AGE_BANDS = ("18-24", "25-34", "35-44", "45-54", "55-64", "65 or older")
EXPERIENCE = ("None", "A little", "Some", "A lot")
DEMOGRAPHICS: tuple[tuple[str, str, tuple[str, ...] | None], ...] = (
    ("age", "Your age", AGE_BANDS),
    ("gender", "Your gender (in your own words)", None),
    ("robots", "Your experience with robots before this study", EXPERIENCE),
    ("ai", "Your experience with artificial intelligence (AI) before this study", EXPERIENCE),
)
"""(id, question, choices or None for free text); every one optional, with
`PREFER_NOT_TO_SAY`."""


def score_nasa_tlx(answers: Mapping[str, float | None]) -> float | None:
    """Raw TLX: the unweighted mean of the six subscales (0-100); None unless all six are
    answered."""
    values = [answers.get(s.id) for s in NASA_TLX]
    if any(v is None for v in values):
        return None
    return sum(float(v) for v in values if v is not None) / len(values)


def score_trust(answers: Mapping[str, float | None]) -> float | None:
    """The checklist's mean (1-7, higher = more trust) after reversing the distrust items;
    None unless all twelve are answered."""
    total = 0.0
    for number in range(1, len(TRUST_ITEMS) + 1):
        value = answers.get(trust_item_id(number))
        if value is None:
            return None
        total += (TRUST_POINTS + 1 - value) if number in TRUST_REVERSED else value
    return total / len(TRUST_ITEMS)


SCALES = {"nasa_tlx": score_nasa_tlx, "trust": score_trust}
"""The scored instruments: name -> score from {item id: numeric answer}."""
