"""tests/in_process.py: a command run in the test's process ends as its own process would
(exit code, stdout, stderr), in the folder and environment it was given, and leaves the
test's process as it found it."""

from __future__ import annotations

import os
from pathlib import Path

from tests import in_process


def test_a_command_in_process_ends_as_its_process_would(tmp_path: Path) -> None:
    folder, environ = Path.cwd(), dict(os.environ)
    seen: list[tuple[Path, str | None, str | None]] = []

    def command(args: list[str]) -> int:
        seen.append((Path.cwd(), os.environ.get("IDEEPRL_PROBE"), os.environ.get("PATH")))
        os.environ["IDEEPRL_LEFT"] = "behind"  # undone after the command
        print(*args)
        return 3

    done = in_process.run(command, ["probe"], ["a", "b"], cwd=tmp_path,
                          env={"IDEEPRL_PROBE": "1", "PATH": None})  # fmt: skip
    assert seen == [(tmp_path, "1", None)]
    assert (done.args, done.returncode, done.stdout, done.stderr) == (
        ["probe", "a", "b"],
        3,
        "a b\n",
        "",
    )
    assert Path.cwd() == folder and dict(os.environ) == environ

    version = in_process.ideeprl("--version")  # argparse's exit, 0
    assert (version.returncode, version.stderr) == (0, "") and version.stdout.startswith("ideeprl ")
    usage = in_process.ideeprl("export", "--no-such-option")
    assert usage.returncode == 2 and usage.stderr.endswith("(see ideeprl export --help)\n")
    failed = in_process.run(lambda args: 1 // 0, ["probe"], [])  # escapes: a traceback, exit 1
    assert failed.returncode == 1 and failed.stderr.rstrip().endswith(
        "ZeroDivisionError: integer division or modulo by zero"
    )
