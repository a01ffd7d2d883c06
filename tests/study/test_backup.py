"""`ideeprl backup` and `ideeprl restore`: a copy taken while a writer commits holds every
row committed before it began and no half of anything after; it restores into a fresh data
folder with the checkpoints its sessions refer to, moved there, and sessions backed up while
they ran resume there to exactly the records of uninterrupted twins. A database at an older
revision is backed up before it is migrated. Runs on PostgreSQL too (DATABASE_URL)."""

from __future__ import annotations

import multiprocessing
import os
import shutil
import signal
import sqlite3
import stat
import threading
import time
from collections.abc import Iterator
from multiprocessing.process import BaseProcess
from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import Engine, select, text
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session

from cli.main import build_parser, main
from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.backup import RESTORED, BackupError, backup, restore
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import alembic_config, upgrade
from study.db.models import Episode, Status, Study, StudySession
from study.services.export import export_study
from study.services.sessions import create_session
from study.services.studies import create_study
from study.settings import Settings
from tests.server.live import fresh_database
from tests.server.scale import session_body
from tests.server.test_resume import records


@pytest.fixture
def installation(tmp_path: Path) -> Iterator[tuple[Engine, Path]]:
    """A migrated database and its data folder."""
    data_dir = tmp_path / "data"
    with fresh_database(data_dir.parent) as url:
        engine = make_engine(url)
        upgrade(engine)
        try:
            yield engine, data_dir
        finally:
            engine.dispose()


def _sessions_with_checkpoints(engine: Engine, data_dir: Path) -> dict[int, bytes]:
    """Two sessions, one running with a step checkpoint, one finished with final.pt."""
    factory = make_session_factory(engine)
    contents = {}
    with factory() as db:
        study = create_study(db, "backed up")
        for status, name in ((Status.running, "step-000000120.pt"), (Status.finished, "final.pt")):
            session = create_session(db, study.id, RunSpec(method="oracle"), data_dir=data_dir)
            path = data_dir / "checkpoints" / f"session-{session.id}" / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(f"checkpoint of {session.id}".encode())
            session.checkpoint_path, session.status = str(path), status.value
            contents[session.id] = path.read_bytes()
        db.commit()
    return contents


class Writer(threading.Thread):
    """Commits one study at a time until told to stop; remembers what was committed."""

    def __init__(self, engine: Engine) -> None:
        super().__init__(daemon=True)
        self.factory = make_session_factory(engine)
        self.committed: list[int] = []
        self.done = threading.Event()

    def run(self) -> None:
        index = 0
        while not self.done.is_set():
            with self.factory() as db:
                study = create_study(db, f"row {index}", description="x" * 500)
                self.committed.append(study.id)
            index += 1


def test_a_backup_taken_while_a_writer_commits_restores_every_committed_row(
    installation: tuple[Engine, Path], tmp_path: Path
) -> None:
    engine, data_dir = installation
    checkpoints = _sessions_with_checkpoints(engine, data_dir)
    (data_dir / "api_key").write_text("the key\n")
    writer = Writer(engine)
    writer.start()
    try:
        while len(writer.committed) < 20:
            time.sleep(0.01)
        before = list(writer.committed)
        args = ["backup", "--out", str(tmp_path / "backup"), "--data-dir", str(data_dir)]
        assert main([*args, "--database-url", engine.url.render_as_string(False)]) == 0
        time.sleep(0.1)
    finally:
        writer.done.set()
        writer.join(30)
    assert len(writer.committed) > len(before)  # the writer ran on through the backup

    fresh = tmp_path / "restored"
    with fresh_database(fresh) as url:
        args = ["restore", str(tmp_path / "backup"), "--data-dir", str(fresh)]
        assert main([*args, "--database-url", url]) == 0
        restored = make_engine(url)
        try:
            if make_url(url).get_backend_name() == "sqlite":
                with sqlite3.connect(make_url(url).database) as raw:
                    assert raw.execute("PRAGMA integrity_check").fetchone() == ("ok",)
            with make_session_factory(restored)() as db:
                ids = set(db.scalars(select(Study.id)))
                sessions = list(db.scalars(select(StudySession).order_by(StudySession.id)))
        finally:
            restored.dispose()
    assert set(before) <= ids, "a row committed before the backup began is missing"
    rows = sorted(i for i in ids if i in set(writer.committed))
    assert rows == writer.committed[: len(rows)], "the copy is not one instant's"
    assert len(sessions) == 2
    for session in sessions:
        path = Path(session.checkpoint_path or "")
        assert path.is_relative_to(fresh) and path.read_bytes() == checkpoints[session.id]
    running, finished = sessions
    assert running.status == "interrupted" and running.status_detail == RESTORED
    assert finished.status == "finished"
    assert (fresh / "api_key").read_text() == "the key\n"


def test_a_backup_follows_a_checkpoint_replaced_meanwhile(
    installation: tuple[Engine, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A worker that records a newer checkpoint and deletes the old one between the
    snapshot and the copy: the backup snapshots again and holds the newer one."""
    import study.db.backup as backups

    engine, data_dir = installation
    _sessions_with_checkpoints(engine, data_dir)
    real_copy = backups.shutil.copyfile
    replaced: list[Path] = []

    def worker_moves_on(source: Path, target: Path) -> object:
        if source.name.startswith("step-") and not replaced:
            newer = source.with_name("step-000000240.pt")
            newer.write_bytes(b"newer")
            with engine.begin() as connection:
                connection.execute(
                    text("UPDATE sessions SET checkpoint_path = :new WHERE checkpoint_path = :old"),
                    {"new": str(newer), "old": str(source)},
                )
            source.unlink()
            replaced.append(newer)
        return real_copy(source, target)

    monkeypatch.setattr(backups.shutil, "copyfile", worker_moves_on)
    done = backup(engine.url.render_as_string(False), data_dir, tmp_path / "backup")
    assert replaced and not done.missing
    relative = str(replaced[0].relative_to(data_dir))
    assert relative in done.files
    assert (tmp_path / "backup" / "files" / relative).read_bytes() == b"newer"


def test_restore_refuses_a_database_that_has_tables(
    installation: tuple[Engine, Path], tmp_path: Path
) -> None:
    engine, data_dir = installation
    url = engine.url.render_as_string(False)
    backup(url, data_dir, tmp_path / "backup")
    with pytest.raises(BackupError, match="has tables already"):
        restore(tmp_path / "backup", url, data_dir)
    with pytest.raises(BackupError, match="exists already"):
        backup(url, data_dir, tmp_path / "backup")


def test_a_backup_and_its_restore_keep_the_data_and_the_key_to_their_owner(
    installation: tuple[Engine, Path], tmp_path: Path
) -> None:
    """The folder holds everyone's data and the researcher key: others may not read either."""
    engine, data_dir = installation
    data_dir.mkdir(exist_ok=True)
    Settings(data_dir=data_dir, api_key="").ensure_api_key()  # 0600, as the server makes it
    url = engine.url.render_as_string(False)
    out = tmp_path / "backup"
    assert (
        main(["backup", "--out", str(out), "--data-dir", str(data_dir), "--database-url", url]) == 0
    )
    assert stat.S_IMODE(out.stat().st_mode) == 0o700
    assert stat.S_IMODE((out / "files" / "api_key").stat().st_mode) == 0o600
    fresh = tmp_path / "restored"
    with fresh_database(fresh) as copy:
        assert main(["restore", str(out), "--data-dir", str(fresh), "--database-url", copy]) == 0
    assert stat.S_IMODE((fresh / "api_key").stat().st_mode) == 0o600
    assert (fresh / "api_key").read_text() == (data_dir / "api_key").read_text()


def _unwritable(tmp_path: Path, kind: str) -> Path:
    """A place no backup can be written to: under a file, or in a folder it may not write."""
    if kind == "under a file":
        (tmp_path / "a file").write_text("")
        return tmp_path / "a file" / "backup"
    if os.geteuid() == 0:
        pytest.skip("root writes into any folder")
    (tmp_path / "read-only").mkdir(mode=0o500)
    return tmp_path / "read-only" / "backup"


@pytest.mark.parametrize("kind", ["under a file", "in a read-only folder"])
def test_a_backup_that_cannot_be_written_says_so_in_one_line(
    installation: tuple[Engine, Path], tmp_path: Path, kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    engine, data_dir = installation
    out = _unwritable(tmp_path, kind)
    url = engine.url.render_as_string(False)
    args = ["backup", "--out", str(out), "--data-dir", str(data_dir), "--database-url", url]
    assert main(args) == 1
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("error: cannot write"), error
    assert str(out.parent) in error
    assert not list(tmp_path.rglob("*.partial"))


def test_a_backup_that_fails_midway_leaves_no_partial_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The backup folder is made, then the database is not there (a wrong --data-dir)."""
    missing = f"sqlite:///{tmp_path / 'data' / 'ideeprl.sqlite3'}"
    out = tmp_path / "backups" / "tonight"
    args = ["backup", "--out", str(out), "--data-dir", str(tmp_path / "data")]
    assert main([*args, "--database-url", missing]) == 1
    assert "no database at" in capsys.readouterr().err
    assert list((tmp_path / "backups").iterdir()) == []


def test_a_database_at_an_older_revision_is_backed_up_before_it_is_migrated(
    tmp_path: Path,
) -> None:
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        try:
            command.upgrade(alembic_config(engine), "0005")
            with engine.begin() as connection:
                connection.execute(
                    text("INSERT INTO studies (name, description, texts, created_at) "
                         "VALUES ('before the migration', '', '{}', CURRENT_TIMESTAMP)")
                )  # fmt: skip
            saved = upgrade(engine, tmp_path / "backups")
            assert saved is not None and saved.parent == tmp_path / "backups"
            assert "pre-migration-0005" in saved.name
            assert upgrade(engine, tmp_path / "backups") is None  # at head: nothing to save
        finally:
            engine.dispose()
        with fresh_database(tmp_path / "copy") as copy:
            restore(saved, copy, tmp_path / "copy")
            old = make_engine(copy)
            try:
                with old.connect() as connection:
                    revision = connection.execute(text("SELECT version_num FROM alembic_version"))
                    assert revision.scalar_one() == "0005"
                    names = connection.execute(text("SELECT name FROM studies")).scalars().all()
            finally:
                old.dispose()
    assert names == ["before the migration"]


def test_a_fresh_database_is_not_backed_up(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'ideeprl.sqlite3'}")
    try:
        assert upgrade(engine) is None
    finally:
        engine.dispose()
    assert not (tmp_path / "backups").exists()


WRITERS = {
    "oracle": session_body("oracle", strategy="alternating", advice_budget=60, episodes=4),
    "autonomous": session_body("autonomous", episodes=4),
}
"""Two machine sessions; the oracle advises all through training, so advice is rewound too."""


def _past_checkpoint(db: Session, session_id: int) -> bool:
    """The session has logged a training episode after its last checkpoint (not its first:
    a resume must rewind rows, not start over)."""
    session = db.get(StudySession, session_id)
    assert session is not None
    query = select(Episode.id).where(
        Episode.session_id == session_id, Episode.last_global_step > session.checkpoint_step
    )
    return session.checkpoint_step > 0 and db.scalar(query.limit(1)) is not None


def _signal(worker: BaseProcess, signum: signal.Signals) -> None:
    assert worker.pid is not None, "started"
    os.kill(worker.pid, signum)


def _hold_past_checkpoints(engine: Engine, workers: dict[int, BaseProcess]) -> None:
    """Stops (SIGSTOP) each worker once it is past a checkpoint, until all are."""
    factory, held = make_session_factory(engine), set()
    deadline = time.monotonic() + 120
    while len(held) < len(workers):
        assert time.monotonic() < deadline, "the sessions never got past a checkpoint"
        for session_id, worker in workers.items():
            with factory() as db:
                status = db.scalar(select(StudySession.status).filter_by(id=session_id))
                assert status in {"created", "running"}, f"session {session_id} ended first"
                if session_id in held or not _past_checkpoint(db, session_id):
                    continue
                _signal(worker, signal.SIGSTOP)
                if _past_checkpoint(db, session_id):  # not checkpointed again meanwhile
                    held.add(session_id)
                else:
                    _signal(worker, signal.SIGCONT)
        time.sleep(0.02)


@pytest.mark.slow
def test_sessions_backed_up_while_they_write_resume_to_the_records_of_uninterrupted_twins(
    tmp_path: Path,
) -> None:
    """Two sessions run in worker processes, each held as soon as it has logged an episode
    after a checkpoint; both go on and `ideeprl backup` runs at once; the workers are then
    killed and the old installation deleted. `ideeprl restore` into a fresh folder and
    database; both resume there (rewinding what they logged after the checkpoint) and hold
    row for row the episodes, steps and advice of twins (the same runs, new sessions)."""
    original, restored, saved = tmp_path / "original", tmp_path / "restored", tmp_path / "b"
    options = WorkerOptions(data_dir=original, checkpoint_every_episodes=2, heartbeat_s=0.2)
    spawn = multiprocessing.get_context("spawn")
    build_parser()  # its imports (torch, seconds) now, not while the sessions run out
    with fresh_database(original) as url:
        engine = make_engine(url)
        upgrade(engine)
        with make_session_factory(engine)() as db:
            study = create_study(db, "backed up while running").id
            runs = [RunSpec.from_json(body["run"]) for body in WRITERS.values()]
            ids = [create_session(db, study, run).id for run in runs]
        workers = {i: spawn.Process(target=run_session, args=(i, url, options)) for i in ids}
        for worker in workers.values():
            worker.start()
        try:
            _hold_past_checkpoints(engine, workers)
            for worker in workers.values():
                _signal(worker, signal.SIGCONT)
            args = ["backup", "--out", str(saved), "--data-dir", str(original)]
            assert main([*args, "--database-url", url]) == 0
        finally:
            for worker in workers.values():
                worker.kill()
                worker.join(30)
            engine.dispose()
    shutil.rmtree(original)  # the restored installation needs nothing of the old one

    with fresh_database(restored) as url:
        args = ["restore", str(saved), "--data-dir", str(restored)]
        assert main([*args, "--database-url", url]) == 0
        engine = make_engine(url)
        factory = make_session_factory(engine)
        try:
            with factory() as db:
                for session_id in ids:  # the copy is of sessions running, past a checkpoint
                    assert _past_checkpoint(db, session_id)
                    status = db.scalar(select(StudySession.status).filter_by(id=session_id))
                    assert status == "interrupted"
                twins = [create_session(db, study, run).id for run in runs]
            options = WorkerOptions(data_dir=restored, checkpoint_every_episodes=2)
            for session_id in [*ids, *twins]:
                assert run_session(session_id, url, options) == "finished", session_id
            with factory() as db:
                counts = export_study(db, study, tmp_path / "export")
            files = {name: (tmp_path / "export" / name).read_bytes() for name in counts}
        finally:
            engine.dispose()
    for method, run, resumed, twin in zip(WRITERS, runs, ids, twins, strict=True):
        got, want = records(files, resumed), records(files, twin)
        trained = [e for e in got["episodes.csv"] if e["stage"] == "train"]
        assert len(trained) == run.config.episodes, method
        assert len(got["advice.csv"]) == (60 if method == "oracle" else 0), method
        for name in got:
            assert got[name] == want[name], (method, name)


def test_pg_dump_is_given_its_password_in_its_environment_not_its_command_line() -> None:
    """A command line is anyone's to read in the process list while a backup runs."""
    from sqlalchemy.engine import make_url

    from study.db.backup import _libpq

    address, env = _libpq(make_url("postgresql+psycopg://ideeprl:s3cret@db.local:5433/study"))
    assert "s3cret" not in address
    assert make_url(address).drivername == "postgresql"
    assert (make_url(address).host, make_url(address).port) == ("db.local", 5433)
    assert env["PGPASSWORD"] == "s3cret"
