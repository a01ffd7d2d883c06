"""`ideeprl report --study ID|NAME --out DIR`: the paper's analysis of a study's sessions."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import (
    EXIT_USAGE,
    add_json_option,
    existing_database,
    find_study,
    print_json,
    service_exit_code,
)

DESCRIPTION = """\
Write the paper's analysis of a study's sessions into a folder: report.md with Figures 5-7
(reward per method with its spread, individual agents, Pearson's correlation), R_T per
agent and method with the improvement over autonomous DeepRL, each comparison's primary
test (Welch's, or the paired t-test over seeds) with the secondary ones, and the paper's
own t-tests, as PNG (with SVG and PDF) and CSV files.

By default the study's finished sessions, except the agent trained as an advisor, grouped
by method; autonomous DeepRL is the baseline when there is one."""


def _ints(values: list[str]) -> tuple[int, ...]:
    try:
        return tuple(int(v) for value in values for v in value.split(",") if v)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--sessions takes session ids, got {' '.join(values)}"
        ) from None


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "report",
        help="write the paper's analysis (figures, R_T, t-tests) of a study's sessions",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--study", required=True, help="study id or name")
    parser.add_argument("--out", type=Path, required=True, help="folder to write into")
    parser.add_argument(
        "--sessions", nargs="+", metavar="ID", help="these sessions only (any status)"
    )
    parser.add_argument("--methods", nargs="+", metavar="METHOD", help="these methods only")
    parser.add_argument("--label", help="sessions with this label only (a batch's name)")
    parser.add_argument(
        "--baseline",
        default="auto",
        help="method to compare against: auto (autonomous if present), none, or a method",
    )
    parser.add_argument(
        "--n-episodes", type=int, help="first N episodes of every agent (runs of unequal length)"
    )
    parser.add_argument("--title", help="report title (default: the study's name)")
    parser.add_argument(
        "--allow-mismatch",
        action="store_true",
        help="also give the t-tests of methods whose settings differ (the warning stays)",
    )
    parser.add_argument(
        "--primary",
        choices=("welch", "paired"),
        default="welch",
        help="each comparison's primary test on the agents' R_T: welch (default), or paired "
        "over seeds (when every agent has a baseline agent of its seed); the others are "
        "reported as secondary",
    )
    parser.add_argument(
        "--reference",
        choices=("authors",),
        help="authors: draw the authors' published mean curves on Figure 5",
    )
    parser.add_argument(
        "--note",
        action="append",
        default=[],
        metavar="TEXT",
        help="a line under the title (how the sessions were run, ...), repeatable",
    )
    add_json_option(parser, "the report as the API describes it (files, R_T per method, notes)")
    add_database_options(parser)
    parser.set_defaults(func=report)


def _fail(message: str, code: int = EXIT_USAGE) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def report(args: argparse.Namespace) -> int:
    from analysis.markdown import versus
    from study.db.engine import make_session_factory
    from study.services.errors import ServiceError
    from study.services.reports import ReportRequest, build_report, describe_report

    try:
        sessions = _ints(args.sessions) if args.sessions else None
    except argparse.ArgumentTypeError as error:
        return _fail(str(error))
    methods = tuple(m for value in args.methods or [] for m in value.split(",") if m) or None
    if args.n_episodes is not None and args.n_episodes < 1:
        return _fail(f"--n-episodes must be at least 1, got {args.n_episodes}")
    if args.out.exists() and not args.out.is_dir():
        return _fail(f"{args.out} is a file; --out takes a folder")
    engine = existing_database(settings_from(args))
    request = ReportRequest(
        sessions=sessions,
        methods=methods,
        label=args.label,
        baseline=args.baseline,
        n_episodes=args.n_episodes,
        title=args.title,
        notes=tuple(args.note),
        allow_mismatch=args.allow_mismatch,
        reference=args.reference,
        primary=args.primary,
    )
    with make_session_factory(engine)() as db:
        study_id, _ = find_study(db, args.study)
        try:
            built = build_report(db, study_id, args.out, request)
        except ServiceError as error:
            return _fail(error.message, service_exit_code(error))
    result = built.result
    warnings = result.audit.warnings() if result.audit is not None else []
    for warning in warnings:
        print(f"warning: {warning}", file=sys.stderr)
    if args.json:
        folder = str(args.out.resolve())
        print_json({**describe_report(study_id, built), "folder": folder, "warnings": warnings})
        return 0
    for note in built.notes:
        if note not in warnings:
            print(f"note: {note}")
    if result.analysis is None:  # the participants alone: no learner finished yet
        print(f"report: {result.report}")
        return 0
    methods_table = result.analysis.methods
    base = result.analysis.baseline
    reference = None if base is None else methods_table.set_index("method").loc[base, "R_T"]
    for _, row in methods_table.iterrows():
        more = "" if base is None else f", {versus(row['R_T'], reference)} vs {base}"
        print(f"{row['name']}: {row['agents']} agents, R_T {row['R_T']:.2f}{more}")
    print(f"figures: {', '.join(p.name for p in result.figures.values())}")
    print(f"tables: {', '.join(p.name for p in result.tables.values())}")
    print(f"report: {result.report}")
    return 0
