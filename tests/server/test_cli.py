import pytest

from cli.main import build_parser


def test_cli_lists_train_and_rejects_unknown_commands(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    with pytest.raises(SystemExit):
        parser.parse_args(["no-such-command"])
    assert "invalid choice" in capsys.readouterr().err
