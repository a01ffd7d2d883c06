"""`ideeprl backup --out DIR` and `ideeprl restore DIR`: a consistent copy of a running
installation (its database and the checkpoints it refers to), and that copy brought back
into a fresh data folder (`study.db.backup`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import EXIT_USAGE, CommandError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "backup",
        help="copy the database and the checkpoints it refers to, while sessions run",
        description="Write a backup folder: the database as of one instant (SQLite's "
        "online backup; pg_dump for PostgreSQL), every checkpoint it refers to, the API key, "
        "and manifest.json. Safe while the server and batch workers run. The database is "
        "found as `ideeprl serve` finds it (IDEEPRL_DATA_DIR, .env, or study_data here).",
    )
    parser.add_argument("--out", type=Path, required=True, help="new folder for the backup")
    add_database_options(parser)
    parser.set_defaults(func=run_backup)

    parser = subparsers.add_parser(
        "restore",
        help="bring a backup back into a fresh data folder (and an empty database)",
        description="Restore a backup folder written by `ideeprl backup` into the data "
        "folder and database given (their database must be empty). Recorded checkpoint "
        "paths move to the new folder; sessions that were running are `interrupted`, "
        "ready to resume from their checkpoints.",
    )
    parser.add_argument("backup", type=Path, help="the backup folder")
    add_database_options(parser)
    parser.set_defaults(func=run_restore)


def run_backup(args: argparse.Namespace) -> int:
    from study.db.backup import BackupError, backup

    settings = settings_from(args)
    try:
        done = backup(settings.db_url, settings.data_dir, args.out)
    except BackupError as error:
        raise CommandError(str(error)) from None
    print(f"{done.folder}: {done.database} database and {len(done.files)} files")
    for path in done.missing:
        print(f"not copied (outside {settings.data_dir}, or gone): {path}")
    return 0


def run_restore(args: argparse.Namespace) -> int:
    from study.db.backup import BackupError, restore

    if not args.backup.is_dir():
        raise CommandError(f"{args.backup} is not a folder; name a backup folder", EXIT_USAGE)
    settings = settings_from(args)
    try:
        done = restore(args.backup, settings.db_url, settings.data_dir)
    except BackupError as error:
        raise CommandError(str(error)) from None
    print(
        f"restored {args.backup} (taken {done.created_at}) into {settings.data_dir}: "
        f"{len(done.files)} files, {done.moved} sessions' paths moved"
    )
    return 0
