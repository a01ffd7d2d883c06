"""`ideeprl validate EXPORT`: check an export (folder or zip, CSV or Parquet) against its
`datapackage.json`: every table there, with the declared columns, each cell of its declared
type (a Parquet column of the declared Arrow type), primary keys present and unique
(`analysis.declared`). `frictionless validate datapackage.json` agrees on a CSV export;
on a Parquet one it reports type errors that are not in the files."""

from __future__ import annotations

import argparse
import json
import sys
import zipfile
from pathlib import Path
from typing import Any

from cli.commands.common import EXIT_RUNTIME, EXIT_USAGE, CommandError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "validate",
        help="check an export (CSV or Parquet) against its datapackage.json",
        description=__doc__,
    )
    parser.add_argument("export", help="the export's folder or zip (ideeprl export, the API)")
    parser.set_defaults(func=validate)


def validate(args: argparse.Namespace) -> int:
    from analysis.declared import problems

    export = Path(args.export)
    descriptor = export / "datapackage.json"
    if not (export.is_file() or descriptor.is_file()):
        raise CommandError(f"{export} is not an export: no datapackage.json there", EXIT_USAGE)
    try:
        found = problems(export)
    except (zipfile.BadZipFile, json.JSONDecodeError, KeyError) as error:
        raise CommandError(f"{export} is not an export: {error}", EXIT_USAGE) from None
    for problem in found:
        print(problem, file=sys.stderr)
    if found:
        raise CommandError(f"{export}: {len(found)} problem(s), above", EXIT_RUNTIME)
    print(f"{export}: valid (every table as its datapackage.json declares)")
    return 0
