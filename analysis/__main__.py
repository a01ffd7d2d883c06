"""`python -m analysis EXPORT OUT`: the report from a study's export (the folder or
zip `ideeprl export` writes, this version's or an older one's), with the comparability
audit and the rescoring; or from a CSV that follows the episode contract; or `--demo` for
made-up curves.

The `ideeprl report --study ID` command reads the database; this one needs only the files,
and chooses an export's sessions as that one does: the finished ones, except trained
advisors (the export's `status` and `advises`) and unchanged replays (`replay_of`), or those
given with `--sessions`. An online study's export adds its participants' section
(`analysis.human_report`), every completed visit whether or not its learner has finished;
with no learner finished it is that section alone, as `ideeprl report` writes it then.
Its exit status is that one's: 0 done, 1 nothing to analyse (no
finished session, sessions that cannot be compared as they are), 2 a usage error (no such
file, not an export or an episode CSV, an option or a value that is not acceptable).
"""

from __future__ import annotations

import argparse
import sys
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.advice import replayed_advice_notes
from analysis.baseline import (
    AUTO,
    NO_BASELINE,
    BaselineError,
    advisors_left_out,
    choose_baseline,
    compare_conditions,
)
from analysis.demo_curves import demo_episodes
from analysis.episodes import CONTRACT, REQUIRED_COLUMNS, EpisodeTableError, arm_of
from analysis.exported import Exported, ExportError, export_of_table, read_export
from analysis.finished import Choice, left_out_notes, nothing_finished
from analysis.human import Visits, learners_finished
from analysis.preregistration import preregistered
from analysis.replays import REPLAYED, unchanged_replays_note
from analysis.report import write_human_report, write_report

CHOOSE = Choice("`--sessions ID ...` and `--episodes N`", "`--episodes {n}`")
"""How this command includes sessions not finished yet, and cuts sessions to a length."""
AFTER = " (and export the study again)"
EXIT_RUNTIME = 1
"""Nothing to analyse: `ideeprl report`'s runtime error."""
EXIT_USAGE = 2
"""No such file, not an export or episode CSV, a value that is not acceptable."""


def _fail(message: str, code: int = EXIT_USAGE) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def _read_csv(path: Path) -> pd.DataFrame | str:
    """The episode CSV at `path`, or what is wrong with it (a usage error)."""
    folder = export_of_table(path)
    if folder is not None:
        return (
            f"{path} is a table of the export {folder}; pass the export's folder ({folder}), "
            "not one of its tables"
        )
    try:
        episodes = pd.read_csv(path)
    except (ValueError, UnicodeDecodeError) as error:  # pandas' ParserError is a ValueError
        return f"{path} is not a CSV ({error}); pass a study's export or an episode CSV"
    missing = [c for c in REQUIRED_COLUMNS if c not in episodes.columns]
    if missing:
        return (
            f"{path} is not an episode table: it lacks column(s) {', '.join(missing)}; pass "
            f"a study's export (its folder or zip) or a CSV of {CONTRACT}"
        )
    return episodes


def _participants_alone(export: Exported, visits: Visits, args: argparse.Namespace) -> int:
    """The report of an online study's participants while none of their learners has
    finished (as `ideeprl report` writes it then)."""
    title = args.title or f"{export.name or 'IDeepRL study'}: the participants"
    notes = [learners_finished(visits), f"Sessions from the export `{args.episodes}`."]
    result = write_human_report(
        visits, args.out_dir, title=title, notes=notes, alpha=export.alpha,
        preregistered=preregistered(export.design),
    )  # fmt: skip
    for path in result.files:
        print(path)
    return 0


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
    parser.add_argument(
        "--baseline",
        default=AUTO,
        help=f"method (or an online study's condition) to improve on; {AUTO!r} (default): "
        f"autonomous DeepRL when there is some, else none; {NO_BASELINE!r}: compare the "
        "methods with each other",
    )
    parser.add_argument("--episodes", type=int, dest="n_episodes", help="keep the first N")
    parser.add_argument(
        "--sessions",
        type=int,
        nargs="+",
        metavar="ID",
        help="an export's sessions to compare, any status (default: the finished ones, "
        "except trained advisors)",
    )
    parser.add_argument("--smoothing", type=int, default=1, help="moving average for plots")
    parser.add_argument(
        "--title", help="the report's title (default: an export's study name, with the paper's)"
    )
    args = parser.parse_args(argv)
    if args.demo == (args.episodes is not None):
        parser.error("give an episode CSV, or --demo without one")
    if not args.demo and not Path(args.episodes).exists():
        return _fail(
            f"no such file or folder: {args.episodes}; pass a study's export (its folder or "
            "zip) or an episode CSV"
        )
    if Path(args.out_dir).exists() and not Path(args.out_dir).is_dir():
        return _fail(f"{args.out_dir} is a file; pass a folder for the report")
    is_export = not args.demo and (
        Path(args.episodes).is_dir() or zipfile.is_zipfile(args.episodes)
    )
    if args.sessions and not is_export:
        parser.error("--sessions chooses an export's sessions; give a study's export")
    extra: dict[str, Any] = {}
    title = "IDeepRL study"
    if args.demo:
        episodes = demo_episodes()
        notes = ["Made-up curves (analysis.demo_curves): a demonstration, not a result."]
    elif is_export:
        try:
            export = read_export(Path(args.episodes), sessions=args.sessions)
        except ExportError as error:
            return _fail(str(error))
        visits = export.visits
        if visits is not None and visits.visits.empty:
            visits = None
        if not export.runs and export.not_finished:
            if visits is None or visits.completed.empty or args.sessions:
                message = nothing_finished(
                    "the export", export.not_finished, CHOOSE.sessions, AFTER
                )
                return _fail(message, EXIT_RUNTIME)
            return _participants_alone(export, visits, args)
        episodes, settings = export.episodes, export.settings
        notes = [
            *([learners_finished(visits)] if visits is not None else []),
            f"Sessions from the export `{args.episodes}`.",
        ]
        left_out = [advisors_left_out(export.advisors)] if export.advisors else []
        if export.unchanged_replays:
            left_out.append(unchanged_replays_note(export.unchanged_replays))
        left_out += left_out_notes(export.not_finished, CHOOSE.sessions, AFTER)
        for note in left_out:
            print(f"note: {note}", file=sys.stderr)
        notes += left_out
        if export.design is not None:  # an online study: its conditions are compared
            # (a session with no condition, a batch run beside the study, keeps its method)
            group = {i: arm_of(run) for i, run in export.runs.items()}
            group |= export.conditions
            episodes, settings, note = compare_conditions(episodes, settings, group, export.alpha)
            notes.append(note)
        if export.replayed_advice is not None:  # each replayed arm: how much advice met its image
            arms = {i: export.conditions.get(i, str(run.method)) for i, run in export.runs.items()}
            replayed = {i: arms[i] for i, run in export.runs.items() if run.method == REPLAYED}
            notes += replayed_advice_notes(export.replayed_advice, replayed)
        extra = {
            "settings": settings,
            "steps": export.steps,
            "alpha": export.alpha,
            "advice": export.advice,
            "visits": visits,
            "strategies": {i: r.strategy if r.advised else None for i, r in export.runs.items()},
            "preregistered": preregistered(export.design),
        }
        title = export.name or title
    else:
        read = _read_csv(Path(args.episodes))
        if isinstance(read, str):
            return _fail(read)
        episodes = read
        notes = [f"Episodes from `{args.episodes}`."]
    try:
        baseline, baseline_notes = choose_baseline(episodes["method"].unique(), args.baseline)
    except BaselineError as error:
        return _fail(str(error))
    try:
        result = write_report(
            episodes,
            args.out_dir,
            title=args.title or f"{title}: the paper's analysis",
            baseline=baseline,
            notes=[*notes, *baseline_notes],
            n_episodes=args.n_episodes,
            smoothing=args.smoothing,
            **extra,
        )
    except EpisodeTableError as error:  # an export's sessions: as `ideeprl report` says it
        if is_export:
            reason = error.worded(CHOOSE.length)
            return _fail(f"these sessions cannot be compared as they are: {reason}", EXIT_RUNTIME)
        return _fail(error.worded(CHOOSE.length))
    for path in result.files:
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
