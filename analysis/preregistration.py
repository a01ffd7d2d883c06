"""A study's pre-registered primary measure and test: the words a design may use for them
(`study.schemas.design.Primary` checks a design against these) and the plan as the report
reads it back from a stored design. Light on purpose: the web app validates designs with
it, without loading scipy."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

CONTINUOUS = ("welch", "mann_whitney")
RATE = ("fisher",)
MEASURES: dict[str, tuple[str, tuple[str, ...]]] = {
    "comparable_score": ("the learners' score over the shared window", CONTINUOUS),
    "advice": ("advice given", CONTINUOUS),
    "accuracy": ("the advice's accuracy", CONTINUOUS),
    "median_decision_s": ("median decision time [s] (log scale)", CONTINUOUS),
    "nasa_tlx": ("NASA-TLX raw", CONTINUOUS),
    "trust": ("trust (Jian, Bisantz and Drury)", CONTINUOUS),
    "check_passed": ("check passed", RATE),
    "completed": ("completed, of those who consented", RATE),
}
"""Each measure a design may name as primary: its words, and the tests that fit it."""
TEST_NAMES = {"welch": "Welch's t", "mann_whitney": "Mann-Whitney U", "fisher": "Fisher's exact"}


@dataclass(frozen=True)
class Preregistered:
    """The primary measure and test a design fixed before the data."""

    measure: str
    test: str
    conditions: tuple[str, str]
    """The two conditions compared (a, b: the effect is a - b)."""
    effect: float | None = None
    """The smallest difference worth detecting, in the measure's units (None: not given)."""

    @property
    def words(self) -> str:
        return MEASURES[self.measure][0]


def problem(measure: str, test: str) -> str | None:
    """Why this measure and test do not go together (None: they do)."""
    if measure not in MEASURES:
        return f"primary.measure must be one of {', '.join(MEASURES)}, not {measure!r}"
    fits = MEASURES[measure][1]
    if test not in fits:
        return f"primary.test for {measure} must be {' or '.join(fits)}, not {test!r}"
    return None


def preregistered(design: Mapping[str, Any] | None) -> Preregistered | None:
    """The plan of a stored design (None where it names no primary measure)."""
    primary = (design or {}).get("primary")
    if not isinstance(primary, Mapping):
        return None
    conditions = primary.get("conditions") or list((design or {}).get("conditions", {}))[:2]
    effect = primary.get("effect")
    return Preregistered(
        str(primary["measure"]),
        str(primary["test"]),
        (str(conditions[0]), str(conditions[1])),
        None if effect is None else float(effect),
    )
