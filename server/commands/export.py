"""`ideeprl export --study ID --out DIR`: a study's CSV files and column dictionary."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write a study's CSV files and column dictionary to a folder",
        description="Write sessions.csv, episodes.csv, steps.csv, advice.csv (with the "
        "advised images in advice/) and columns.csv, the column dictionary.",
    )
    parser.add_argument("--study", type=int, required=True, help="study id")
    parser.add_argument("--out", type=Path, required=True, help="folder to write into")
    parser.set_defaults(func=export)


def export(args: argparse.Namespace) -> int:
    from server.db.engine import make_engine, make_session_factory
    from server.db.migrate import upgrade
    from server.services.errors import ServiceError
    from server.services.export import export_study
    from server.settings import Settings

    settings = Settings()
    engine = make_engine(settings.db_url)
    upgrade(engine)
    with make_session_factory(engine)() as db:
        try:
            counts = export_study(db, args.study, args.out)
        except ServiceError as error:
            print(f"error: {error.message}")
            return 2
    for name, rows in counts.items():
        print(f"{args.out / name}: {rows} rows")
    print(f"{args.out / 'columns.csv'}: the column dictionary")
    return 0
