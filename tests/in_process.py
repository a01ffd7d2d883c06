"""`ideeprl ARGS` and `python -m analysis ARGS` run in the test's own process, for a test
that needs a command's work and what it prints, not a process of its own: each process
started pays seconds of imports (torch, pandas, sqlalchemy). A test of what only a process
shows (a signal, a kill, a terminal, the exit of an interpreter, what a fresh one loads, the
installed script, a server) starts one.

Each call gives what `subprocess.run(..., capture_output=True, text=True)` would: the exit
code (argparse's too; an exception that escapes the command is exit 1 with its traceback
on stderr, as Python ends a script), stdout and stderr. What a command may change in the
process is put back after it: the environment and the working folder it ran in, the root
logger's handlers and level, the SIGINT and SIGTERM handlers, and torch's threads where
torch was loaded before it."""

from __future__ import annotations

import io
import logging
import os
import signal
import sys
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from pathlib import Path
from subprocess import CompletedProcess

ROOT = Path(__file__).absolute().parents[1]
"""The checkout, where the tests' processes run `ideeprl`."""


def ideeprl(
    *args: str, cwd: Path = ROOT, env: Mapping[str, str | None] | None = None
) -> CompletedProcess[str]:
    """`ideeprl ARGS` (`cli.main.main`) in this process, in `cwd`, with `env`'s variables
    set (None: unset) for the command alone."""
    from cli.main import main

    return run(main, ["ideeprl"], args, cwd=cwd, env=env)


def analysis(
    *args: str, cwd: Path = ROOT, env: Mapping[str, str | None] | None = None
) -> CompletedProcess[str]:
    """`python -m analysis ARGS` (`analysis.__main__.main`) in this process, as `ideeprl`."""
    from analysis.__main__ import main

    return run(main, ["python", "-m", "analysis"], args, cwd=cwd, env=env)


def run(
    main: Callable[[list[str]], int | None],
    program: Sequence[str],
    args: Sequence[str],
    *,
    cwd: Path = ROOT,
    env: Mapping[str, str | None] | None = None,
) -> CompletedProcess[str]:
    """`main(ARGS)` as the process `program ARGS` would end (the module's docstring)."""
    out, err = io.StringIO(), io.StringIO()
    with _isolated(cwd, env or {}), redirect_stdout(out), redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as stopped:  # argparse: --help, --version, a usage error
            code = stopped.code if isinstance(stopped.code, int | None) else 1
            if isinstance(stopped.code, str):
                print(stopped.code, file=sys.stderr)
        except Exception:
            traceback.print_exc()
            code = 1
    return CompletedProcess([*program, *args], int(code or 0), out.getvalue(), err.getvalue())


@contextmanager
def _isolated(cwd: Path, env: Mapping[str, str | None]) -> Iterator[None]:
    environ = dict(os.environ)
    folder = Path.cwd()
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    signals = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    threads = _torch_threads()
    try:
        for key, value in env.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        os.chdir(cwd)
        yield
    finally:
        os.chdir(folder)
        if dict(os.environ) != environ:
            os.environ.clear()
            os.environ.update(environ)
        root.handlers[:] = handlers
        root.setLevel(level)
        for number, handler in signals.items():
            if handler is not None and signal.getsignal(number) is not handler:
                signal.signal(number, handler)
        if threads is not None and _torch_threads() != threads:
            import torch

            torch.set_num_threads(threads)


def _torch_threads() -> int | None:
    """Torch's CPU threads, where this process has loaded torch (None: it has not)."""
    torch = sys.modules.get("torch")
    return None if torch is None else int(torch.get_num_threads())
