"""`ideeprl` behaves like a well-kept command-line tool: --version, a study by id or name,
exit 1 for runtime errors and 2 for usage, no bars into a pipe, and commands that read
find the data folder as `serve` does and never create an empty database."""

from __future__ import annotations

import fcntl
import json
import os
import struct
import subprocess
import sys
import termios
import threading
from importlib import metadata
from pathlib import Path

import pytest

from cli.commands.common import show_progress
from cli.main import main
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.services.export import TABLES
from study.services.studies import create_study
from tests import in_process
from tests.server.live import free_port

ROOT = Path(__file__).absolute().parents[2]
TINY_TRAIN = [
    "--episodes", "2", "--set", "pretraining_steps=40", "--set", "batch_size=8",
    "--set", "memory_size=200", "--set", "max_episode_steps=15", "--set", "advice_budget=0",
]  # fmt: skip


def environment(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("IDEEPRL_")}
    env.pop("DATABASE_URL", None)
    return {**env, "PYTHONPATH": str(ROOT), **extra}


def ideeprl(*args: str, cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    """`ideeprl ARGS` in a process of its own, in `cwd`, in `environment(**env)`."""
    return subprocess.run(
        [sys.executable, "-m", "cli", *args],
        cwd=cwd,
        env=environment(**env),
        capture_output=True,
        text=True,
        timeout=300,
    )


def here(*args: str, cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    """`ideeprl ARGS` in the test's process, in `cwd`, with the variables `environment`
    gives a process: none of IDEEPRL_ or DATABASE_URL but `env`'s."""
    unset: dict[str, str | None] = {k: None for k in os.environ if k.startswith("IDEEPRL_")}
    return in_process.ideeprl(*args, cwd=cwd, env={**unset, "DATABASE_URL": None, **env})


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A data folder as `serve` leaves it: a migrated database holding one study. A database
    URL in the environment would win over the folder (as it does for `serve`), so the
    in-process commands here run without one."""
    monkeypatch.delenv("DATABASE_URL", raising=False)
    monkeypatch.delenv("IDEEPRL_DATABASE_URL", raising=False)
    folder = tmp_path / "data"
    folder.mkdir()
    engine = make_engine(f"sqlite:///{folder / 'ideeprl.sqlite3'}")
    upgrade(engine)
    with make_session_factory(engine)() as db:
        create_study(db, "pilot study", description="for the CLI tests")
    engine.dispose()
    return folder


def test_version_prints_the_installed_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:
        main(["--version"])
    assert stopped.value.code == 0
    assert capsys.readouterr().out.strip() == f"ideeprl {metadata.version('ideeprl')}"


@pytest.mark.slow
def test_export_by_name_or_id_finds_the_data_folder_as_serve_does(
    data_dir: Path, tmp_path: Path
) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    by_name = here(
        "export", "--study", "pilot study", "--out", str(tmp_path / "a"),
        cwd=elsewhere, IDEEPRL_DATA_DIR=str(data_dir),
    )  # fmt: skip
    assert by_name.returncode == 0, by_name.stderr
    assert (tmp_path / "a" / "sessions.csv").is_file()
    by_id = here(
        "export", "--study", "1", "--out", str(tmp_path / "b"), "--data-dir", str(data_dir),
        cwd=elsewhere,
    )  # fmt: skip
    assert by_id.returncode == 0, by_id.stderr
    # Like serve, a `.env` in the working folder names the data folder too.
    (elsewhere / ".env").write_text(f"IDEEPRL_DATA_DIR={data_dir}\n")
    dotenv = here("export", "--study", "pilot study", "--out", str(tmp_path / "c"), cwd=elsewhere)
    assert dotenv.returncode == 0, dotenv.stderr
    assert list(elsewhere.iterdir()) == [elsewhere / ".env"]


@pytest.mark.slow
def test_reading_commands_never_create_an_empty_database(tmp_path: Path) -> None:
    for command in (["export"], ["report"]):
        done = here(*command, "--study", "1", "--out", str(tmp_path / "out"), cwd=tmp_path)
        assert done.returncode == 1, done.stderr
        assert "error: no database at" in done.stderr and "--data-dir" in done.stderr
    assert list(tmp_path.iterdir()) == [], "no study_data folder, no database, no output"


def test_unknown_studies_are_runtime_errors_and_bad_options_usage_errors(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flags = ["--data-dir", str(data_dir)]
    out = str(tmp_path / "out")
    assert main(["export", "--study", "no such study", "--out", out, *flags]) == 1
    assert "error: no study with name no such study; studies: 1 (pilot study)" in (
        capsys.readouterr().err
    )
    assert main(["report", "--study", "pilot study", "--out", out, *flags]) == 1
    assert "study 1 has no sessions yet: run some first" in capsys.readouterr().err
    assert main(["report", "--study", "1", "--n-episodes", "0", "--out", out, *flags]) == 2
    # a study made by name from the command line follows the API's rule for names
    assert main(["batch", "--study", "   ", "--methods", "autonomous", *flags]) == 2
    assert "name must not be blank" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stopped:
        main(["export", "--no-such-option"])
    assert stopped.value.code == 2
    assert not Path(out).exists()


BAD_DESIGN = """\
name: several bad values
design:
  capacity: lots
  colour: blue
  conditions:
    early:
      run: {method: human, config: {batch_size: 0}}
    late:
      run: {method: human, strategy: late, config: {advice_budget: 5}}
"""


def test_a_design_file_with_several_bad_values_names_each_one_a_line(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every bad value of a design file, pydantic's and the conditions' runs', by its field
    as the API's 422 names it, one a line; a usage error, and no study made. One bad value
    keeps the one-line form."""
    source = tmp_path / "design.yaml"
    source.write_text(BAD_DESIGN)
    flags = ["--data-dir", str(data_dir)]
    assert main(["study", "create", "--from", str(source), *flags]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.splitlines() == [
        f"error: {source}: 4 bad values:",
        "  design.capacity: Input should be a valid integer",
        "  design.colour: unknown field 'colour'; valid fields: conditions, capacity, alpha, "
        "idle_limit_s, pool, panel, check, questionnaire, primary",
        "  design.conditions.early.run.config.batch_size: config.batch_size must be an "
        "integer from 1 to 4096",
        '  design.conditions.late.run.strategy: strategy must be one of "early", '
        '"alternating", "importance", "mistake_correcting"',
    ]
    source.write_text(BAD_DESIGN.replace("capacity: lots", "capacity: 4").replace(
        "  colour: blue\n", "").replace("batch_size: 0", "batch_size: 8").replace(
        "strategy: late, ", ""))  # fmt: skip
    assert main(["study", "create", "--from", str(source), *flags]) == 0
    source.write_text(BAD_DESIGN.replace("name: several", "name: one").replace(
        "capacity: lots", "capacity: 4").replace("  colour: blue\n", "").replace(
        "strategy: late, ", ""))  # fmt: skip
    assert main(["study", "create", "--from", str(source), *flags]) == 2
    assert capsys.readouterr().err == (
        f"error: {source}: design.conditions.early.run.config.batch_size: "
        "config.batch_size must be an integer from 1 to 4096\n"
    )


def test_json_output_is_all_of_stdout_and_keeps_the_exit_codes(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Scripts parse stdout: with --json it is one JSON object (nothing else writes there,
    not even a library in the process), or nothing on an error."""
    flags = ["--data-dir", str(data_dir), "--json"]
    out = tmp_path / "out"
    done = ideeprl("export", "--study", "pilot study", "--out", str(out), *flags, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    printed = json.loads(done.stdout)
    assert printed == {
        "study_id": 1,
        "folder": str(out.resolve()),
        "format": "csv",
        "rows": {f"{table}.csv": 0 for table in TABLES},
    }
    assert main(["export", "--study", "no such study", "--out", str(out), *flags]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and "error: no study with name no such study" in captured.err
    assert main(["report", "--study", "pilot study", "--out", str(out), *flags]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and "has no sessions yet" in captured.err
    assert main(["report", "--study", "1", "--n-episodes", "0", "--out", str(out), *flags]) == 2
    assert capsys.readouterr().out == ""


@pytest.mark.slow
def test_printed_database_urls_hide_the_password(tmp_path: Path) -> None:
    """`serve`'s banner goes to the journal, which more people read than the `.env`; a
    database that is down (here: a PostgreSQL port nothing listens on) is one line, not a
    traceback. The URL is given here, never the environment's own DATABASE_URL."""
    port = free_port()
    url = f"postgresql://ideeprl:s3cret@127.0.0.1:{port}/ideeprl"
    data = str(tmp_path / "data")
    served = ideeprl(
        "serve", "--port", str(free_port()), cwd=tmp_path, DATABASE_URL=url, IDEEPRL_DATA_DIR=data
    )
    assert f"database:        postgresql+psycopg://ideeprl:***@127.0.0.1:{port}/" in served.stdout
    # nor the researcher key: where it is, not what it is (at a terminal it is shown)
    key = (tmp_path / "data" / "api_key").read_text().strip()
    assert key not in served.stdout
    assert f"researcher key:  in {tmp_path / 'data' / 'api_key'}" in served.stdout
    commands = [
        served,
        here("batch", "--study", "pilot", "--methods", "autonomous", "--dry-run", "--json",
             "--database-url", url, cwd=tmp_path),
        here("export", "--study", "1", "--out", str(tmp_path / "out"), "--database-url", url,
             cwd=tmp_path),
    ]  # fmt: skip
    for done in commands:
        assert "s3cret" not in done.stdout + done.stderr
        assert done.returncode == 1, done.stderr
        assert done.stderr.startswith("error: the database did not answer: ")
        assert done.stderr.count("\n") == 1, done.stderr
        assert f"port {port} failed" in done.stderr


class FakeTerminal:
    def __init__(self, tty: bool) -> None:
        self.tty = tty

    def isatty(self) -> bool:
        return self.tty


def test_what_is_printed_of_a_database_and_its_errors() -> None:
    """Every command prints its database through `shown_url` (a batch's lines, its dry run,
    its --json, serve's banner); only a database that cannot be reached is one line, other
    database errors (a lock in the middle of the work) keep their traceback."""
    from sqlalchemy.exc import OperationalError

    from cli.commands.common import shown_url, unreachable

    assert (
        shown_url("postgresql+psycopg://u:s3cret@h:5432/d") == "postgresql+psycopg://u:***@h:5432/d"
    )
    assert (
        shown_url("sqlite:///study_data/ideeprl.sqlite3") == "sqlite:///study_data/ideeprl.sqlite3"
    )
    down = Exception('connection failed: connection to server at "127.0.0.1", port 1 failed')
    locked = Exception("database is locked")
    assert unreachable(OperationalError("SELECT 1", {}, down))
    assert not unreachable(OperationalError("INSERT ...", {}, locked))


def test_progress_bars_only_for_a_terminal() -> None:
    assert show_progress(False, FakeTerminal(True)) is True
    assert show_progress(False, FakeTerminal(False)) is False
    assert show_progress(True, FakeTerminal(True)) is False


def train_output(tmp_path: Path, *, terminal: bool) -> str:
    """Everything `ideeprl train` writes on stderr, into a pipe or into a terminal (a pty)."""
    command = [sys.executable, "-m", "cli", "train", "--out", str(tmp_path), *TINY_TRAIN]
    if not terminal:
        done = subprocess.run(
            command, cwd=ROOT, env=environment(), capture_output=True, text=True, timeout=300
        )
        assert done.returncode == 0, done.stderr
        return done.stderr
    master, slave = os.openpty()
    # A pty starts 0 columns wide, where tqdm draws an empty bar: make it a usual 80.
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    chunks: list[bytes] = []

    def drain() -> None:
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:
                return
            if not data:
                return
            chunks.append(data)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    with subprocess.Popen(
        command, cwd=ROOT, env=environment(), stdout=subprocess.DEVNULL, stderr=slave
    ) as process:
        os.close(slave)
        assert process.wait(timeout=300) == 0
    reader.join(timeout=10)
    os.close(master)
    return b"".join(chunks).decode(errors="replace")


@pytest.mark.slow
def test_train_draws_bars_in_a_terminal_and_none_into_a_pipe(tmp_path: Path) -> None:
    piped = train_output(tmp_path / "piped", terminal=False)
    assert "%|" not in piped and "\r" not in piped
    shown = train_output(tmp_path / "tty", terminal=True)
    assert "%|" in shown, "the same run at a terminal shows its bars"


def test_a_usage_error_is_the_error_and_where_the_usage_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run's command has some 60 flags: its whole usage before the error buried it. A bad
    flag's value is said as it was typed."""
    db = ["--database-url", f"sqlite:///{tmp_path / 'x.sqlite3'}"]
    with pytest.raises(SystemExit) as exited:
        main(["batch", "--study", "s", "--methods", "autonomous", "--episodes", "0", *db])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [
        "ideeprl batch: error: argument --episodes: config.episodes must be an integer from 1 "
        "to 100000 (given: '0')",
        "(see ideeprl batch --help)",
    ], err
    flags = ["--set", "batch_size=abc", "--dry-run", *db]
    assert main(["batch", "--study", "s", "--methods", "autonomous", *flags]) == 2
    assert "(given: 'abc')" in capsys.readouterr().err


def test_serve_refuses_to_start_with_figure_formats_it_does_not_write(tmp_path: Path) -> None:
    """A figure format the report cannot write stops the server at its start, saying which
    and what the formats are, instead of failing each report a researcher asks for later."""
    done = here(
        "serve", "--data-dir", str(tmp_path), "--port", "1", cwd=tmp_path,
        IDEEPRL_FIGURE_FORMATS="png,jpg",
    )  # fmt: skip
    assert done.returncode == 2, done
    assert "the server does not start: unknown figure format(s) jpg" in done.stderr
    assert "png, svg, pdf" in done.stderr
    assert not (tmp_path / "ideeprl.sqlite3").exists(), "refused before it touched the data"
