"""A consistent copy of an installation while it runs, and its restore into a fresh folder.

A backup is a folder: the database as of one instant (SQLite's online backup API; for
PostgreSQL, `pg_dump` of a snapshot exported from the transaction that also reads the
checkpoint paths), every checkpoint and fitted advisor model that database refers to
(copied under `files/`, by its path relative to the data folder), the generated API key,
and `manifest.json`.

Why the checkpoints are consistent with the database: a worker saves a checkpoint file
(atomically) before it records its path, and deletes the previous file only after. So a
file the snapshot refers to exists until the worker has recorded a newer one; if it is gone
before we copy it, the snapshot is taken again (and only the files new to it are copied).

Restoring writes the database and the files into a data folder whose database is empty,
moves the recorded paths from the old data folder to the new one, and marks the sessions
that were running or paused `interrupted`: they resume from their checkpoint, with exactly
the records an uninterrupted run would have written (the worker rewinds past it).
"""

from __future__ import annotations

import getpass
import json
import os
import shutil
import sqlite3
import subprocess
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import JSON, Engine, create_engine, inspect, select, text, update
from sqlalchemy import column as sa_column
from sqlalchemy import table as sa_table
from sqlalchemy.engine import URL, make_url

from study.db.models import LIVE_STATUSES, Status

MANIFEST = "manifest.json"
SQLITE_FILE = "database.sqlite3"
POSTGRES_FILE = "database.dump"
FILES = "files"
API_KEY_FILE = "api_key"
ATTEMPTS = 20
"""Snapshots taken at most while workers keep replacing the checkpoints just referred to."""
RESTORED = "restored from a backup taken while it ran; resume it"


class BackupError(RuntimeError):
    """A backup or restore that cannot be done, with what to do about it."""


@dataclass(frozen=True)
class Backup:
    folder: Path
    database: str
    """sqlite or postgresql."""
    files: list[str]
    """Checkpoints (and the API key) copied, relative to the data folder."""
    missing: list[str]
    """Paths the database refers to that were not there (outside the data folder or gone)."""


@dataclass(frozen=True)
class Restored:
    """A backup restored."""

    created_at: str
    """When the backup was taken (ISO 8601)."""
    files: list[str]
    """The files it put back, relative to the data folder."""
    moved: int
    """Sessions whose paths were moved from the backup's data folder to the new one."""


def _is_sqlite(url: URL) -> bool:
    return url.get_backend_name() == "sqlite"


def _libpq(url: URL) -> tuple[str, dict[str, str]]:
    """The URL as pg_dump and pg_restore take it (no SQLAlchemy driver name, no password),
    and their environment with the password in `PGPASSWORD`: a command line is anyone's to
    read in the process list while a (nightly) backup runs."""
    env = dict(os.environ)
    if url.password is not None:
        env["PGPASSWORD"] = str(url.password)
    bare = URL.create("postgresql", url.username, None, url.host, url.port, url.database, url.query)
    return bare.render_as_string(hide_password=False), env


RUN_PATHS = ("advisor_checkpoint", "fitted_model")
"""The fields of a stored run that name a file: the advising checkpoint, the fitted model."""


def _run_paths(run: Any) -> dict[str, str]:
    """The files a stored run names (`sessions.run`, JSON or its text), by field."""
    if isinstance(run, str):
        run = json.loads(run)
    return {name: path for name in RUN_PATHS if (path := (run or {}).get(name))}


def _referenced(rows: Any, run_document: bool = True) -> list[str]:
    """The paths rows of (checkpoint_path, run) name: `run_document` False for a database
    from before migration 0007, whose rows give (checkpoint_path, advisor_checkpoint)."""
    return sorted(
        {
            path
            for checkpoint, run in rows
            for path in (
                checkpoint,
                *(_run_paths(run).values() if run_document else [run]),
            )
            if path
        }
    )


PATHS = "SELECT checkpoint_path, run FROM sessions"
PATHS_BEFORE_0007 = "SELECT checkpoint_path, advisor_checkpoint FROM sessions"
SESSIONS = sa_table(
    "sessions", sa_column("id"), sa_column("checkpoint_path"), sa_column("run", JSON)
)


def _snapshot_sqlite(url: URL, out: Path) -> list[str]:
    """The database as of one instant into `out`; the paths it refers to."""
    assert url.database, "a SQLite URL names its file"
    if not Path(url.database).is_file():
        raise BackupError(f"no database at {Path(url.database).resolve()}")
    source = sqlite3.connect(url.database, timeout=30)
    target = sqlite3.connect(out)
    try:
        source.execute("PRAGMA busy_timeout=30000")
        source.backup(target)  # one step: a read transaction, so one instant
        columns = {row[1] for row in target.execute("PRAGMA table_info(sessions)")}
        query = PATHS if "run" in columns else PATHS_BEFORE_0007
        return _referenced(target.execute(query).fetchall(), "run" in columns)
    finally:
        target.close()
        source.close()


def _snapshot_postgres(url: URL, out: Path) -> list[str]:
    engine = create_engine(url, isolation_level="REPEATABLE READ")
    try:
        with engine.connect() as connection, connection.begin():
            snapshot = connection.execute(text("SELECT pg_export_snapshot()")).scalar_one()
            columns = set(
                connection.execute(
                    text(
                        "SELECT column_name FROM information_schema.columns "
                        "WHERE table_name = 'sessions' AND table_schema = current_schema()"
                    )
                ).scalars()
            )
            query = PATHS if "run" in columns else PATHS_BEFORE_0007
            paths = _referenced(connection.execute(text(query)).all(), "run" in columns)
            address, env = _libpq(url)
            done = subprocess.run(
                ["pg_dump", "--format=custom", f"--snapshot={snapshot}", "--no-owner",
                 f"--file={out}", address],
                capture_output=True, text=True, env=env,
            )  # fmt: skip
            if done.returncode != 0:
                raise BackupError(f"pg_dump failed: {done.stderr.strip()}")
        return paths
    finally:
        engine.dispose()


def _relative(path: str, data_dir: Path) -> Path | None:
    """`path` inside the data folder, relative to it; None outside it. Relative paths are
    the working folder's, as the server and workers that wrote them saw them."""
    here = Path.cwd()
    found, base = here / path, here / data_dir  # an absolute right side wins
    for inside, folder in ((found, base), (found.resolve(), base.resolve())):
        if inside.is_relative_to(folder):
            return inside.relative_to(folder)
    return None


def _copy_private(source: Path, target: Path) -> None:
    """Copy `source` to a file only its owner may read (the researcher key), never readable
    by others on the way: a plain copy takes the umask's 0644."""
    fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.fchmod(fd, 0o600)  # a file that was there keeps its mode through O_CREAT: not once written
    with os.fdopen(fd, "wb") as f:
        f.write(source.read_bytes())


def _make_private_folder(work: Path, out: Path) -> None:
    """`work` (and its `files/`), mode 0700: a backup holds every participant's data."""
    shutil.rmtree(work, ignore_errors=True)
    try:
        work.parent.mkdir(parents=True, exist_ok=True)
        work.mkdir(mode=0o700)
        work.chmod(0o700)  # whatever the umask
        (work / FILES).mkdir()
    except OSError as error:
        shutil.rmtree(work, ignore_errors=True)
        raise BackupError(
            f"cannot write into {out.parent} ({error.strerror}); name a folder that the user "
            f"{_user()} can write (one it owns)"
        ) from None


def _user() -> str:
    """This process's user's name (its uid where it has none, as in some containers)."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return str(os.getuid())


def backup(database_url: str, data_dir: Path, out: Path) -> Backup:
    """A consistent copy of the database and the checkpoints it refers to, in `out` (a
    folder that must not exist yet, made readable by this user alone). A backup that fails
    leaves nothing behind."""
    url = make_url(database_url)
    if out.exists():
        raise BackupError(f"{out} exists already; name a new folder for the backup")
    work = out.with_name(f".{out.name}.partial")
    _make_private_folder(work, out)
    try:
        done = _copy_into(url, data_dir, work)
    except (OSError, sqlite3.Error) as error:
        shutil.rmtree(work, ignore_errors=True)
        raise BackupError(f"the backup into {out} failed: {error}") from None
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    work.rename(out)
    return Backup(out, done.database, done.files, done.missing)


def _copy_into(url: URL, data_dir: Path, work: Path) -> Backup:
    """The backup's contents written into the folder `work`."""
    database = work / (SQLITE_FILE if _is_sqlite(url) else POSTGRES_FILE)
    copied: set[Path] = set()
    for _ in range(ATTEMPTS):
        database.unlink(missing_ok=True)
        snapshot = _snapshot_sqlite if _is_sqlite(url) else _snapshot_postgres
        paths = snapshot(url, database)
        gone, missing, wanted = False, [], set()
        for path in paths:
            relative = _relative(path, data_dir)
            if relative is None:
                missing.append(path)
                continue
            wanted.add(relative)
            if relative in copied:
                continue
            target = work / FILES / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                shutil.copyfile(data_dir / relative, target)
            except FileNotFoundError:
                if Path(path).name.startswith("step-"):  # replaced meanwhile: snapshot again
                    gone = True
                else:
                    missing.append(path)
                continue
            copied.add(relative)
        if not gone:
            break
        time.sleep(0.2)
    else:
        raise BackupError(
            f"the workers replaced their checkpoints faster than {ATTEMPTS} snapshots could "
            "copy them; try again (or pause sessions first)"
        )
    for stale in copied - wanted:
        (work / FILES / stale).unlink()
    files = sorted(str(p) for p in wanted - {Path(m) for m in missing})
    key = data_dir / API_KEY_FILE
    if key.is_file():
        _copy_private(key, work / FILES / API_KEY_FILE)
        files.append(API_KEY_FILE)
    manifest = _manifest(
        url,
        database,
        data_dir=str(data_dir),
        data_dir_resolved=str(data_dir.resolve()),
        files=files,
        missing=missing,
    )
    (work / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    return Backup(work, url.get_backend_name(), files, missing)


def _manifest(url: URL, database: Path, **contents: Any) -> dict[str, Any]:
    """A backup's manifest: its format, when, the database's kind and file, and `contents`."""
    return {
        "format": "ideeprl-backup",
        "version": 1,
        "created_at": datetime.now(UTC).isoformat(),
        "database": url.get_backend_name(),
        "database_file": database.name,
        **contents,
    }


def backup_database(engine: Engine, out: Path) -> Path:
    """The database alone (no files), as of one instant, into the folder `out`: what a
    schema migration could spoil."""
    url = engine.url
    out.mkdir(parents=True, exist_ok=False)
    database = out / (SQLITE_FILE if _is_sqlite(url) else POSTGRES_FILE)
    (_snapshot_sqlite if _is_sqlite(url) else _snapshot_postgres)(url, database)
    manifest = _manifest(url, database, files=[], missing=[])
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    return database


def read_manifest(folder: Path) -> dict[str, Any]:
    try:
        manifest = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError):
        raise BackupError(f"{folder} is not a backup (no readable {MANIFEST})") from None
    if manifest.get("format") != "ideeprl-backup":
        raise BackupError(f"{folder / MANIFEST} is not an ideeprl backup's manifest")
    return dict(manifest)


def restore(folder: Path, database_url: str, data_dir: Path) -> Restored:
    """The backup in `folder` into an empty database and the data folder `data_dir`."""
    manifest = read_manifest(folder)
    url = make_url(database_url)
    if manifest["database"] != url.get_backend_name():
        raise BackupError(
            f"the backup holds a {manifest['database']} database; restore it into one "
            f"(--database-url), not {url.get_backend_name()}"
        )
    if _is_sqlite(url) and url.database:
        Path(url.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url)
    try:
        with engine.connect() as connection:
            if inspect(connection).get_table_names():
                raise BackupError(
                    "the target database has tables already; restore into an empty one "
                    "(a fresh --data-dir, or a new PostgreSQL database)"
                )
    finally:
        engine.dispose()
    source = folder / manifest["database_file"]
    if _is_sqlite(url):
        assert url.database, "a SQLite URL names its file"
        with sqlite3.connect(source) as reading, sqlite3.connect(url.database) as writing:
            reading.backup(writing)
    else:
        address, env = _libpq(url)
        done = subprocess.run(
            ["pg_restore", "--no-owner", "--exit-on-error", f"--dbname={address}",
             str(source)],
            capture_output=True, text=True, env=env,
        )  # fmt: skip
        if done.returncode != 0:
            raise BackupError(f"pg_restore failed: {done.stderr.strip()}")
    for name in manifest["files"]:
        target = data_dir / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if name == API_KEY_FILE:
            _copy_private(folder / FILES / name, target)
        else:
            shutil.copyfile(folder / FILES / name, target)
    moved = _move_paths(url, manifest, data_dir)
    return Restored(created_at=manifest["created_at"], files=list(manifest["files"]), moved=moved)


def _move_paths(url: URL, manifest: dict[str, Any], data_dir: Path) -> int:
    """Recorded paths under the old data folder now point into `data_dir`; sessions that
    were live are `interrupted` (their workers are not coming back)."""
    old = Path(manifest.get("data_dir") or ".")
    engine = create_engine(url)
    try:
        with engine.begin() as connection:
            columns = {c["name"] for c in inspect(connection).get_columns("sessions")}
            if "run" in columns:
                moved = _move_run_paths(connection, old, manifest, data_dir)
            else:  # a database from before migration 0007
                moved = _move_paths_before_0007(connection, old, manifest, data_dir)
            live = ", ".join(f"'{s.value}'" for s in LIVE_STATUSES)
            connection.execute(
                text(
                    "UPDATE sessions SET status = :status, status_detail = :detail "
                    f"WHERE status IN ({live})"
                ),
                {"status": Status.interrupted.value, "detail": RESTORED},
            )
    finally:
        engine.dispose()
    return moved


def _move_run_paths(connection: Any, old: Path, manifest: dict[str, Any], data_dir: Path) -> int:
    """The checkpoint paths and the files the run documents name (`RUN_PATHS`) moved."""
    moved = 0
    rows = connection.execute(
        select(SESSIONS.c.id, SESSIONS.c.checkpoint_path, SESSIONS.c.run)
    ).all()
    for session_id, checkpoint, run in rows:
        values: dict[str, Any] = {}
        relative = _relative_to_old(checkpoint, old, manifest)
        if relative is not None:
            values["checkpoint_path"] = str(data_dir / relative)
        moves = {
            name: str(data_dir / relative)
            for name, path in _run_paths(run).items()
            if (relative := _relative_to_old(path, old, manifest)) is not None
        }
        if moves:
            run = json.loads(run) if isinstance(run, str) else dict(run)
            values["run"] = {**run, **moves}
        if values:
            connection.execute(update(SESSIONS).where(SESSIONS.c.id == session_id).values(**values))
            moved += 1
    return moved


def _move_paths_before_0007(
    connection: Any, old: Path, manifest: dict[str, Any], data_dir: Path
) -> int:
    """`_move_paths` for a database whose sessions still have their run's columns."""
    moved = 0
    rows = connection.execute(
        text("SELECT id, checkpoint_path, advisor_checkpoint FROM sessions")
    ).all()
    for session_id, checkpoint, advisor in rows:
        values = {}
        for column, path in (("checkpoint_path", checkpoint), ("advisor_checkpoint", advisor)):
            relative = _relative_to_old(path, old, manifest)
            if relative is not None:
                values[column] = str(data_dir / relative)
        if values:
            sets = ", ".join(f"{c} = :{c}" for c in values)
            connection.execute(
                text(f"UPDATE sessions SET {sets} WHERE id = :id"), {**values, "id": session_id}
            )
            moved += 1
    return moved


def _relative_to_old(path: str | None, old: Path, manifest: dict[str, Any]) -> Path | None:
    if not path:
        return None
    for base in (str(old), manifest.get("data_dir_resolved") or ""):
        if base and (path == base or path.startswith(base.rstrip("/") + "/")):
            return Path(path[len(base.rstrip("/")) + 1 :])
    return None
