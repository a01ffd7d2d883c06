"""Spreadsheet formulas neutralised in CSV cells: a cell a spreadsheet would run
(`=HYPERLINK(...)`, `+cmd`, `@SUM`) gets a leading apostrophe, which spreadsheets show
as text and which a reader strips. Numbers stay numbers; only text is touched."""

from __future__ import annotations

from typing import Any

FORMULA_START = ("=", "+", "-", "@", "\t", "\r", "\n", "\uff1d", "\uff0b", "\uff0d", "\uff20")
"""Characters that start a formula (with their full-width forms some spreadsheets accept)."""


def safe_cell(value: Any) -> Any:
    if isinstance(value, str) and value.startswith(FORMULA_START):
        return "'" + value
    return value


def safe_frame(frame: Any) -> Any:
    """A pandas DataFrame with every text cell, column name and index label made safe."""
    safe = frame.map(safe_cell)
    safe.columns = [safe_cell(c) for c in safe.columns]
    safe.index = [safe_cell(i) for i in safe.index]
    safe.index.name = frame.index.name
    return safe
