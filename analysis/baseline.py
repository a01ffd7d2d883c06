"""What a report compares, and which method (or online condition) it measures the others
against.

One rule for the report from the database (`ideeprl report`, the API) and the one from an
export (`python -m analysis EXPORT OUT`): an online study's conditions stand where methods
stand; `auto` takes autonomous DeepRL when the report has it, else compares the methods
with each other; `none` never names a baseline; any other name must have sessions in the
report.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # (the web process reads AUTO from here, without pandas)
    import pandas as pd

AUTO = "auto"
"""The baseline is autonomous DeepRL when present, else none."""
NO_BASELINE = "none"
"""No baseline: the methods are compared with each other, no improvement in percent."""


def advisors_left_out(session_ids: Iterable[int], failed: Iterable[int] = ()) -> str:
    """The note on the trained advisors a report leaves out, for both report paths: every
    advisor a batch trained for the agent method (each attempt, used or not); `failed`: those
    whose stored check failed (known from the database, not from an export)."""
    ids = sorted(session_ids)
    failed = sorted(failed)
    checks = (
        f" ({len(failed)} failed their check: session(s) {', '.join(map(str, failed))})"
        if failed
        else ""
    )
    return (
        f"Left out session(s) {', '.join(map(str, ids))}: advisor(s) trained for the "
        f"agent-IDeepRL method{checks}, not compared agents."
    )


class BaselineError(ValueError):
    """A named baseline with no sessions in the report."""


def choose_baseline(methods: Iterable[str], baseline: str) -> tuple[str | None, list[str]]:
    """The baseline to use for `methods` and the notes the report gives about the choice."""
    present = set(methods)
    if baseline == NO_BASELINE:
        return None, []
    if baseline == AUTO:
        if "autonomous" in present:
            return "autonomous", []
        return None, [
            "No autonomous DeepRL sessions in this report, so no improvement in percent: "
            "the methods are compared with each other (or name one of them as the baseline)."
        ]
    if baseline not in present:
        raise BaselineError(
            f"baseline method {baseline!r} has no sessions in this report (methods: "
            f"{', '.join(sorted(present))}); name one of them, {AUTO!r} or {NO_BASELINE!r}"
        )
    return baseline, []


def compare_conditions(
    episodes: pd.DataFrame, settings: pd.DataFrame, group: Mapping[int, str], alpha: float
) -> tuple[pd.DataFrame, pd.DataFrame, str]:
    """An online study's episodes and settings with each session's `group` (its condition,
    or its method where it has none) as its method, and the report's note saying so."""
    return (
        episodes.assign(method=episodes["session_id"].map(group)),
        settings.assign(method=settings["session_id"].map(group)),
        f"An online study: its conditions are compared, at α = {alpha:g}.",
    )
