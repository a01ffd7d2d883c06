"""`ideeprl export --study ID|NAME --out DIR`: a study's tables and their data package."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import (
    CommandError,
    add_json_option,
    existing_database,
    find_study,
    print_json,
    service_exit_code,
)


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write a study's tables (CSV or Parquet) and their data package to a folder",
        description="Write sessions, episodes, steps and advice tables (with the advised "
        "images in advice/), datapackage.json (Frictionless: each column's type, unit and "
        "description) and columns.csv, the same dictionary. The database "
        "is found as `ideeprl serve` finds it (IDEEPRL_DATA_DIR, .env, or study_data here).",
    )
    parser.add_argument("--study", required=True, help="study id or name")
    parser.add_argument("--out", type=Path, required=True, help="folder to write into")
    parser.add_argument(
        "--format", choices=("csv", "parquet"), default="csv", help="table format (default csv)"
    )
    parser.add_argument(
        "--panel-ids",
        action="store_true",
        help="an online study's panel ids as they are, for payment (default: pseudonymous)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier export in --out (a folder holding anything else is refused)",
    )
    add_json_option(parser, "the folder, the format and each table file's row count")
    add_database_options(parser)
    parser.set_defaults(func=export)


def export(args: argparse.Namespace) -> int:
    from study.db.engine import make_session_factory
    from study.services.errors import ServiceError
    from study.services.export import clear_earlier_export, export_study

    if args.out.exists() and not args.out.is_dir():
        raise CommandError(f"{args.out} is a file; --out takes a folder", code=2)
    engine = existing_database(settings_from(args))
    with make_session_factory(engine)() as db:
        study_id, _ = find_study(db, args.study)  # an unknown study says so first
        used = args.out.is_dir() and any(args.out.iterdir())
        if used and not args.overwrite:
            raise CommandError(
                f"{args.out} is not empty: export into a new or empty folder, or add "
                "--overwrite to replace an earlier export there",
                code=2,
            )
        try:
            if used:
                clear_earlier_export(args.out)
            counts = export_study(db, study_id, args.out, args.format, panel_ids=args.panel_ids)
        except ServiceError as error:
            raise CommandError(error.message, service_exit_code(error)) from None
    if args.json:
        folder = str(args.out.resolve())
        print_json({"study_id": study_id, "folder": folder, "format": args.format, "rows": counts})
        return 0
    for name, rows in counts.items():
        print(f"{args.out / name}: {rows} rows")
    print(f"{args.out / 'datapackage.json'}: the data package (types, units, descriptions)")
    print(f"{args.out / 'columns.csv'}: the column dictionary")
    return 0
