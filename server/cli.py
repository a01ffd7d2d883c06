"""The `ideeprl` command line: one entry point, a sub-command per task.

`train` comes from the learner; every module in `server/commands/` that defines
`register(subparsers)` adds its own sub-commands, so a new command is a new file.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from collections.abc import Sequence

from server import commands


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ideeprl",
        description="Human advising studies in interactive deep reinforcement learning.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    modules = ["learner.cli"] + [
        f"{commands.__name__}.{info.name}" for info in pkgutil.iter_modules(commands.__path__)
    ]
    for name in modules:
        module = importlib.import_module(name)
        register = getattr(module, "register", None)
        if register is not None:
            register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
