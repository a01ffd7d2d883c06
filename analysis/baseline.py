"""Which method (or online condition) a report measures the others against.

One rule for the report from the database (`ideeprl report`, the API) and the one from an
export (`python -m analysis EXPORT OUT`): `auto` takes autonomous DeepRL when the report
has it, else compares the methods with each other; `none` never names a baseline; any
other name must have sessions in the report.
"""

from __future__ import annotations

from collections.abc import Iterable

AUTO = "auto"
"""The baseline is autonomous DeepRL when present, else none."""
NO_BASELINE = "none"
"""No baseline: the methods are compared with each other, no improvement in percent."""


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
            "the methods are compared with each other. Add the baseline with "
            "`ideeprl batch --methods autonomous` in the same study, or name another "
            "method as the baseline."
        ]
    if baseline not in present:
        raise BaselineError(
            f"baseline method {baseline!r} has no sessions in this report (methods: "
            f"{', '.join(sorted(present))}); name one of them, {AUTO!r} or {NO_BASELINE!r}"
        )
    return baseline, []
