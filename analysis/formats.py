"""The formats the report's figures are written in, and the setting that picks them: a
module of its own, without matplotlib, so the web process checks the setting at its start
(`server.main.create_app`) without loading the plotting library."""

from __future__ import annotations

import os
from collections.abc import Sequence

FIGURE_FORMATS = ("png", "svg", "pdf")
"""The formats a figure is written in: the PNG the report links and the dashboard shows,
and the SVG and PDF a paper's figures are set in."""
FIGURE_FORMATS_VARIABLE = "IDEEPRL_FIGURE_FORMATS"
"""The environment variable naming the formats to write, comma-separated (`png`: the PNGs
alone, as the tests write them); unset or empty: all of `FIGURE_FORMATS`."""


def figure_formats(formats: str | Sequence[str] | None = None) -> tuple[str, ...]:
    """The formats a figure is written in, in `FIGURE_FORMATS`' order: `formats` (names,
    or one comma-separated text), else `FIGURE_FORMATS_VARIABLE`'s, else all. The PNG is
    always among them: the report links it and the dashboard shows it."""
    if formats is None:
        formats = os.environ.get(FIGURE_FORMATS_VARIABLE, "").strip() or FIGURE_FORMATS
    if isinstance(formats, str):
        formats = formats.split(",")
    named = {f.strip().lower() for f in formats} - {""}
    unknown = named - set(FIGURE_FORMATS)
    if unknown:
        raise ValueError(
            f"unknown figure format(s) {', '.join(sorted(unknown))}: the formats are "
            f"{', '.join(FIGURE_FORMATS)} ({FIGURE_FORMATS_VARIABLE}, comma-separated)"
        )
    return tuple(f for f in FIGURE_FORMATS if f == "png" or f in named)
