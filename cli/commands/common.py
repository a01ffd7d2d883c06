"""What every `ideeprl` command shares: exit codes, finding the data folder and a study,
whether to draw progress bars, and the flags of a run (train, batch, replay).

Commands whose result a script reads take `--json`: one JSON object on stdout and nothing
else there (messages and warnings go to stderr), with the same exit codes.

Exit codes follow the usual convention: 0 done, 1 a runtime error (no such study, nothing
to analyse, a database that is not there), 2 a usage error (an option that makes no
sense, or a value the database refuses as invalid; argparse's own errors are 2 too),
130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any, TextIO

from sqlalchemy.engine import make_url

from learner.fields import FieldError, given_arguments, leaves, parse_text

if TYPE_CHECKING:
    from sqlalchemy.engine import Engine
    from sqlalchemy.exc import OperationalError
    from sqlalchemy.orm import Session

    from learner.run import RunSpec
    from study.settings import Settings

EXIT_RUNTIME = 1
EXIT_USAGE = 2


class CommandError(Exception):
    """An error a command reports in one line and exits with `code`."""

    def __init__(self, message: str, code: int = EXIT_RUNTIME) -> None:
        super().__init__(message)
        self.message = message
        self.code = code


def service_exit_code(error: Exception) -> int:
    """A service's `Invalid` (a value the user gave is not acceptable) is a usage error;
    `NotFound` and `Conflict` (what the database holds) are runtime errors."""
    from study.services.errors import Invalid

    return EXIT_USAGE if isinstance(error, Invalid) else EXIT_RUNTIME


def fail(message: str, code: int = EXIT_RUNTIME) -> int:
    """Print `error: message` on stderr; returns the exit code."""
    print(f"error: {message}", file=sys.stderr)
    return code


def add_json_option(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument(
        "--json",
        action="store_true",
        help=f"print {what} as one JSON object on stdout, and nothing else there "
        "(messages go to stderr); the exit codes stay the same",
    )


def print_json(value: Any) -> None:
    """The result of a command run with `--json`: its only output on stdout."""
    print(json.dumps(value, indent=2))


def show_progress(disabled: bool, stream: TextIO | None = None) -> bool:
    """Progress bars only for a person at a terminal: never when the output is piped or
    redirected to a file (logs then hold the results, not thousands of bar redraws)."""
    stream = stream or sys.stderr
    return not disabled and bool(getattr(stream, "isatty", lambda: False)())


def shown_url(url: str) -> str:
    """A database URL as it may be printed: its password hidden (`serve`'s banner goes to
    the journal, a batch's output to logs)."""
    return make_url(url).render_as_string(hide_password=True)


def database_down(error: OperationalError) -> str:
    """What to say, in one line, when the database does not answer (a PostgreSQL server that
    is down, a wrong password or host)."""
    reason = " ".join(str(error.orig or error).split())
    return (
        f"the database did not answer: {reason}; check that it runs and that "
        "--database-url, DATABASE_URL or the .env file here name it"
    )


UNREACHABLE = (
    "connection failed",
    "connection refused",
    "could not connect",
    "could not translate host name",
    "authentication failed",
    "timeout expired",
    "does not exist",
    "unable to open database file",
    "no route to host",
)
"""What a driver's error says when the database cannot be reached at all (psycopg, and
SQLite's file that cannot be opened): only these become `database_down`'s one line."""


def unreachable(error: OperationalError) -> bool:
    """The database could not be reached (down, wrong host, password or name), rather than
    failing in the middle of the work (a lock, a deadlock, a full disk), which keeps its
    traceback."""
    text = str(error.orig or error).lower()
    return any(sign in text for sign in UNREACHABLE)


def check_database(url: str) -> None:
    """Connect once, so that a database that is down raises here (`cli.main` says so in one
    line) and not inside uvicorn's start-up, which logs a traceback."""
    from study.db.engine import make_engine

    engine = make_engine(url)
    try:
        with engine.connect():
            pass
    finally:
        engine.dispose()


def existing_database(settings: Settings) -> Engine:
    """An engine on the database `serve` uses with these settings, migrated, for a command
    that only reads: a SQLite file that does not exist is an error that says where we
    looked, never a new empty database."""
    from study.db.engine import make_engine
    from study.db.migrate import BACKUPS, upgrade

    url = make_url(settings.db_url)
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        from pathlib import Path

        path = Path(url.database)
        if not path.is_file():
            raise CommandError(
                f"no database at {path.resolve()}: run this where you run `ideeprl serve`, "
                "or pass --data-dir (or set IDEEPRL_DATA_DIR) to the folder holding "
                "ideeprl.sqlite3, or --database-url"
            )
    engine = make_engine(settings.db_url)
    upgrade(engine, settings.data_dir / BACKUPS)
    return engine


def find_study(db: Session, study: str) -> tuple[int, str]:
    """The study named by id or by name (never created); returns (id, description)."""
    from sqlalchemy import select

    from study.db.models import Study

    text = study.strip()
    found = db.get(Study, int(text)) if text.isdigit() else None
    if found is None:
        found = db.scalar(select(Study).where(Study.name == text))
    if found is None:
        names = [f"{s.id} ({s.name})" for s in db.scalars(select(Study).order_by(Study.id))]
        known = f"; studies: {', '.join(names)}" if names else "; there are no studies yet"
        what = "id" if text.isdigit() else "name"
        raise CommandError(f"no study with {what} {text}{known}")
    return found.id, f"study {found.id} ({found.name})"


# --- a run's flags, shared by the commands that take a run (train, batch, replay) ---------
DEPRECATED = {
    "--threads": "torch_threads",
    "--budget": "advice_budget",
    "--oracle-error-rate": "error_rate",
}
"""Older names of some flags, still read (each prints that it is deprecated)."""


def add_deprecated(parser: argparse.ArgumentParser, skip: tuple[str, ...] = ()) -> None:
    """The older names of generated flags (`DEPRECATED`), hidden from --help."""
    for flag, name in DEPRECATED.items():
        if name not in skip:
            parser.add_argument(flag, dest=f"deprecated__{name}", help=argparse.SUPPRESS)
    if "method" not in skip:  # the advisor was a flag before the method was the run's
        parser.add_argument("--advisor", dest="deprecated_advisor", help=argparse.SUPPRESS)


def add_set_option(group: argparse._ActionsContainer, help: str) -> None:
    """`--set FIELD=VALUE`, repeatable: any field of the run by its leaf name (read by
    `given_values`, which checks the name and the value)."""
    group.add_argument(
        "--set",
        dest="assignments",
        action="append",
        type=_parse_assignment,
        default=[],
        metavar="FIELD=VALUE",
        help=f"{help} (VALUE as JSON, else a string); repeatable",
    )


def given_values(args: argparse.Namespace, declaration: type[RunSpec]) -> dict[str, Any]:
    """The run's leaves the flags gave (generated flags, `--set FIELD=VALUE`, deprecated
    names), by leaf name, each checked; `FieldError` for a bad one."""
    by_name = {leaf.name: leaf for leaf in leaves(declaration)}
    values: dict[str, Any] = {}
    for name, text in getattr(args, "assignments", None) or []:
        if name not in by_name:
            raise FieldError(
                name, f"--set: unknown field {name[:64]}; valid: {', '.join(sorted(by_name))}"
            )
        values[name] = parse_text(by_name[name], text)
    for key, text in vars(args).items():
        if key.startswith("deprecated__") and text is not None:
            name = key.removeprefix("deprecated__")
            print(
                f"warning: {_old_flag(name)} is deprecated; use {by_name[name].flag}",
                file=sys.stderr,
            )
            values[name] = parse_text(by_name[name], text)
    advisor = getattr(args, "deprecated_advisor", None)
    if advisor is not None:
        print("warning: --advisor is deprecated; use --method", file=sys.stderr)
        values["method"] = parse_text(
            by_name["method"], "autonomous" if advisor == "none" else advisor
        )
    values.update(given_arguments(args))
    return values


def _old_flag(name: str) -> str:
    return next(flag for flag, leaf in DEPRECATED.items() if leaf == name)


def _parse_assignment(item: str) -> tuple[str, str]:
    name, sep, value = item.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError("--set takes FIELD=VALUE")
    return name.strip(), value
