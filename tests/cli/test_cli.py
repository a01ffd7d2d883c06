import pytest

from cli.main import build_parser


def test_cli_lists_train_and_rejects_unknown_commands(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    with pytest.raises(SystemExit):
        parser.parse_args(["no-such-command"])
    assert "invalid choice" in capsys.readouterr().err


def _commands(parser) -> set[str]:
    import argparse

    (subparsers,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return set(subparsers.choices)


def test_a_command_named_like_its_module_loads_that_module_alone() -> None:
    """`ideeprl batch` registers `cli/commands/batch.py` only; `--help` and the commands
    that live elsewhere (`train`, `restore`) still see every command."""
    import subprocess
    import sys

    everything = _commands(build_parser())
    assert {"train", "batch", "serve", "backup", "restore", "study"} <= everything
    assert _commands(build_parser(command="batch")) == {"batch"}
    assert _commands(build_parser(command="restore")) == everything
    assert _commands(build_parser(command="common")) == everything, "a helper module"
    probe = (
        "import sys; from cli.main import build_parser; build_parser(command='batch'); "
        "print(sorted(m for m in sys.modules if m.startswith('cli.commands.')))"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    assert "cli.commands.batch" in loaded and "cli.commands.serve" not in loaded, loaded
