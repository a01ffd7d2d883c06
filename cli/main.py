"""The `ideeprl` command line: one entry point, a sub-command per task.

Every module in `cli/commands/` that defines `register(subparsers)` adds its own
sub-commands, so a new command is a new file. A command named like its module (`ideeprl
batch` is `cli/commands/batch.py`) loads that module alone; anything else (`--help`,
`restore`, a typo) loads them all, so the listing and argparse's messages are whole. A
usage error is two lines, the error and where the usage is. Exit
codes: 0 done, 1 a runtime error, 2 a usage error, 130 interrupted
(`cli.commands.common`).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence
from importlib import metadata
from typing import NoReturn

from sqlalchemy.exc import OperationalError

from cli import commands
from cli.commands.common import CommandError, database_down, fail, unreachable


class Parser(argparse.ArgumentParser):
    """argparse's parser (its sub-commands' too), a usage error in two lines: the error and
    where the usage is. A run's command has some 60 flags: the whole usage printed before
    the error buried it."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n(see {self.prog} --help)\n")


def version() -> str:
    """The installed distribution's version (pyproject.toml)."""
    try:
        return metadata.version("ideeprl")
    except metadata.PackageNotFoundError:  # run from a checkout that is not installed
        return "unknown (not installed)"


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Every command's parser, or only `command`'s where a module of `cli/commands/` is
    named after it; the commands that take a run (`train`, `batch`) make their flags from
    the run's declaration (`learner.run.declared`)."""
    parser = Parser(
        prog="ideeprl",
        description="Human advising studies in interactive deep reinforcement learning.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    found = pkgutil.iter_modules(commands.__path__)
    modules = [f"{commands.__name__}.{info.name}" for info in found]
    own = f"{commands.__name__}.{command}"
    if own in modules and command != "common":
        modules = [own]
    for name in modules:
        module = importlib.import_module(name)
        register = getattr(module, "register", None)
        if register is None:
            continue
        register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    given = list(sys.argv[1:] if argv is None else argv)
    command = given[0] if given and not given[0].startswith("-") else None
    args = build_parser(command).parse_args(given)
    try:
        return int(args.func(args) or 0)
    except CommandError as error:
        return fail(error.message, error.code)
    except OperationalError as error:
        if not unreachable(error):
            raise
        return fail(database_down(error))


if __name__ == "__main__":
    raise SystemExit(main())
