"""`python -m analysis EXPORT OUT`: the report from a study's export (the folder or
zip `ideeprl export` writes, this version's or an older one's), with the comparability
audit and the rescoring; or from a CSV that follows the episode contract; or `--demo` for
made-up curves.

The `ideeprl report --study ID` command reads the database; this one needs only the files.
"""

from __future__ import annotations

import argparse
import sys
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.demo_curves import demo_episodes
from analysis.episodes import CONTRACT, EpisodeTableError
from analysis.exported import ExportError, read_export
from analysis.report import write_report


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m analysis",
        description="Write the paper's analysis (figures, CSV tables, report.md) for episodes.",
        epilog=f"The CSV has {CONTRACT}.",
    )
    parser.add_argument(
        "episodes", nargs="?", help="a study's export (folder or zip), or an episode CSV"
    )
    parser.add_argument("out_dir", help="folder for the report")
    parser.add_argument("--demo", action="store_true", help="use made-up curves, not a CSV")
    parser.add_argument("--baseline", default="autonomous", help="method to improve on")
    parser.add_argument("--episodes", type=int, dest="n_episodes", help="keep the first N")
    parser.add_argument("--smoothing", type=int, default=1, help="moving average for plots")
    parser.add_argument("--title", default="IDeepRL study: the paper's analysis")
    args = parser.parse_args(argv)
    if args.demo == (args.episodes is not None):
        parser.error("give an episode CSV, or --demo without one")
    extra: dict[str, Any] = {}
    if args.demo:
        episodes = demo_episodes()
        notes = ["Made-up curves (analysis.demo_curves): a demonstration, not a result."]
    elif Path(args.episodes).is_dir() or zipfile.is_zipfile(args.episodes):
        try:
            export = read_export(Path(args.episodes))
        except ExportError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        episodes = export.episodes
        extra = {"settings": export.settings, "steps": export.steps}
        notes = [f"Sessions from the export `{args.episodes}`."]
    else:
        episodes = pd.read_csv(args.episodes)
        notes = [f"Episodes from `{args.episodes}`."]
    try:
        result = write_report(
            episodes,
            args.out_dir,
            title=args.title,
            baseline=args.baseline,
            notes=notes,
            n_episodes=args.n_episodes,
            smoothing=args.smoothing,
            **extra,
        )
    except EpisodeTableError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    for path in result.files:
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
