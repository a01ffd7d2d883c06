"""Markdown tables and number formats for the report, without extra dependencies."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping

import pandas as pd

Formatter = Callable[[object], str]
REPORT_FILE = "report.md"
"""The report's own file in its folder (the web app names it without loading the analysis)."""


def _is_missing(value: object) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def fixed(digits: int) -> Formatter:
    """A number with `digits` decimals; missing values as an en dash."""
    return lambda v: "–" if _is_missing(v) else f"{float(v):.{digits}f}"  # type: ignore[arg-type]


def signed_pct(value: object) -> str:
    """A percentage with its sign, e.g. "+64.03 %"."""
    return "–" if _is_missing(value) else f"{float(value):+.2f} %"  # type: ignore[arg-type]


def versus(value: object, reference: object) -> str:
    """`value` against `reference`: in percent ("+64.03 %") where the reference is
    positive, else the difference in points ("+2.00 points"); a percentage of a negative
    or zero score reads as a gain or loss it is not."""
    if _is_missing(value) or _is_missing(reference):
        return "–"
    value, reference = float(value), float(reference)  # type: ignore[arg-type]
    if reference > 0:
        return signed_pct((value - reference) / reference * 100.0)
    return f"{value - reference:+.2f} points"


def p_value(value: object) -> str:
    """Four significant digits, scientific below 0.001 (6.395e-14), as the paper prints."""
    if _is_missing(value):
        return "–"
    p = float(value)  # type: ignore[arg-type]
    return f"{p:.4e}" if p < 1e-3 else f"{p:.4f}"


def whole(value: object) -> str:
    """A whole number such as a seed, even when pandas stored it as float for a gap."""
    if _is_missing(value):
        return "–"
    number = float(value)  # type: ignore[arg-type]
    return str(int(number)) if number.is_integer() else str(value)


def plain(value: object) -> str:
    """Anything else, as text; missing values as an en dash."""
    return "–" if _is_missing(value) else str(value).replace("|", "\\|")


def table(
    frame: pd.DataFrame,
    columns: Mapping[str, str],
    formats: Mapping[str, Formatter] | None = None,
    empty: str | None = None,
) -> str:
    """A Markdown table of `frame`: `columns` maps column -> header, in the order shown;
    `empty`, a sentence said instead of a table with no rows (a header alone says nothing)."""
    if empty is not None and frame.empty:
        return f"*{empty}*"
    formats = formats or {}
    lines = [
        "| " + " | ".join(columns.values()) + " |",
        "|" + "|".join("---" for _ in columns) + "|",
    ]
    for _, row in frame.iterrows():
        cells = [formats.get(c, plain)(row[c]) for c in columns]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def count(n: int, noun: str) -> str:
    """ "1 agent", "3 agents": a number with its noun (the plural by an s)."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def some(values: Iterable[object], limit: int = 5) -> str:
    """ "4, 5, 6 and 2 more": the first `limit` values, then how many are left."""
    items = [str(v) for v in values]
    more = f" and {len(items) - limit} more" if len(items) > limit else ""
    return ", ".join(items[:limit]) + more
