"""The replication's saved state (`state/`): its database in parts, each under 50 MB, and
the advisors with their checks.

    python state.py save DATA STATE      # DATA's finished runs into STATE/db/*.sqlite3.gz
    python state.py restore STATE DATA   # the parts merged back into DATA/ideeprl.sqlite3
    python state.py open STATE OUT       # the same, into the file OUT (for the analysis)

The database is split by session: `db/STUDY/LABEL/session-ID.sqlite3.gz` holds the
database's schema with that one finished session, its steps, episodes and advice, and the
tables of no session (studies), so any one part opens on its own, a finished run adds one
file (about 0.5 MB) and changes none, and the parts merge back with their session ids
unchanged (the advisors' checkpoint paths and the procedure runs' schedules
name them). Unfinished runs are dropped, as before: their checkpoints stay on the machine
that ran them and the batch makes them anew.

`save` also writes each advisor as an agent advisor reads it (config, seed, metadata and
the network: about 1 MB) under `STATE/advisors/`, with the checks stored beside it
(`final.pt.check.json`), and `restore` copies them back. Runs with the tag's code first
on `sys.path` (commands.sh does), for `learner.checkpoint`.
"""

from __future__ import annotations

import gzip
import re
import shutil
import sqlite3
import sys
import tempfile
from pathlib import Path

UNFINISHED = "select id from sessions where status != 'finished'"


def _tables(db: sqlite3.Connection) -> list[str]:
    rows = db.execute(
        "select name from sqlite_master where type = 'table' and name != 'sqlite_sequence'"
    ).fetchall()
    return [name for (name,) in rows]


def _with_session(db: sqlite3.Connection) -> list[str]:
    return [
        t
        for t in _tables(db)
        if "session_id" in [c[1] for c in db.execute(f"pragma table_info({t})")]
    ]


def _drop_sessions(db: sqlite3.Connection, where: str) -> None:
    """Delete the sessions `select id from sessions where ...` names, and their rows."""
    gone = f"select id from sessions where {where}"
    for table in _with_session(db):
        db.execute(f"delete from {table} where session_id in ({gone})")
    db.execute(f"delete from sessions where {where}")


def part_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "_", name)


def _part(whole: sqlite3.Connection, session_id: int, out: Path) -> None:
    """A database of `whole`'s schema with one session (and its rows) and the small tables
    that belong to no session (studies, alembic_version)."""
    db = sqlite3.connect(out)
    schema = whole.execute(
        "select sql from sqlite_master where sql is not null and name not like 'sqlite_%' "
        "order by type = 'index'"
    ).fetchall()
    for (sql,) in schema:
        db.execute(sql)
    db.commit()
    db.execute("attach ? as w", (str(whole_path(whole)),))
    for table in _tables(whole):
        columns = [c[1] for c in whole.execute(f"pragma table_info({table})")]
        if table == "sessions":
            where = f" where id = {session_id}"
        elif "session_id" in columns:
            where = f" where session_id = {session_id}"
        else:
            where = ""
        db.execute(f"insert into main.{table} select * from w.{table}{where}")
    db.execute("delete from main.sqlite_sequence")
    db.execute("insert into main.sqlite_sequence select * from w.sqlite_sequence")
    db.commit()
    db.execute("detach w")
    db.execute("vacuum")
    db.close()


def whole_path(db: sqlite3.Connection) -> str:
    return db.execute("pragma database_list").fetchone()[2]


def save(data: Path, state: Path) -> None:
    """Each finished session not yet saved into its own part: STATE/db/STUDY/LABEL/
    session-ID.sqlite3.gz (a finished session does not change, so a saved part is kept as
    it is and a new run adds one file)."""
    from learner.checkpoint import read_checkpoint, write_checkpoint

    src = sqlite3.connect(data / "ideeprl.sqlite3")
    parts_dir = state / "db"
    with tempfile.TemporaryDirectory() as tmp:
        whole_file = Path(tmp) / "whole.sqlite3"
        whole = sqlite3.connect(whole_file)
        src.backup(whole)
        src.close()
        _drop_sessions(whole, f"id in ({UNFINISHED})")
        whole.commit()
        sessions = whole.execute(
            "select s.id, t.name, s.label from sessions s join studies t on t.id = s.study_id"
        ).fetchall()
        paths = {
            p
            for (p,) in whole.execute(
                "select distinct json_extract(run, '$.advisor_checkpoint') from sessions "
                "where json_extract(run, '$.advisor_checkpoint') is not null "
                "union select checkpoint_path from sessions where label like '% advisor' "
                "and checkpoint_path is not null"
            )
        }
        for session_id, study, label in sessions:
            target = (
                parts_dir / part_name(study) / part_name(label) / f"session-{session_id}.sqlite3.gz"
            )
            if target.exists():
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            part = Path(tmp) / f"session-{session_id}.sqlite3"
            _part(whole, session_id, part)
            with open(part, "rb") as raw, gzip.GzipFile(target, "wb", 9, mtime=0) as packed:
                shutil.copyfileobj(raw, packed)
            part.unlink()
            print(f"{target.relative_to(state)}: {target.stat().st_size / 1e6:.2f} MB")
        whole.close()
    for path in sorted(paths):
        relative = Path(path).relative_to(data)
        target = state / "advisors" / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        if Path(path).resolve() != target.resolve():
            s = read_checkpoint(path)
            if not target.exists():
                write_checkpoint(
                    target,
                    {
                        "config": s["config"],
                        "seed": s["seed"],
                        "metadata": s["metadata"],
                        "agent": {"network": s["agent"]["network"]},
                    },
                )
        check = Path(str(path) + ".check.json")
        if check.is_file():
            shutil.copyfile(check, str(target) + ".check.json")
        print("advisor", relative, "(with its checks)" if check.is_file() else "")


def merge(state: Path, out: Path) -> None:
    """Every part of `state/db` into the new database `out`."""
    parts = sorted((state / "db").rglob("*.sqlite3.gz"))
    if not parts:
        raise SystemExit(f"{state / 'db'} has no parts")
    out.parent.mkdir(parents=True, exist_ok=True)
    with gzip.open(parts[0], "rb") as packed, open(out, "wb") as raw:
        shutil.copyfileobj(packed, raw)
    db = sqlite3.connect(out)
    tables = _tables(db)
    for path in parts[1:]:
        with tempfile.NamedTemporaryFile(suffix=".sqlite3") as tmp:
            with gzip.open(path, "rb") as packed:
                shutil.copyfileobj(packed, tmp)
            tmp.flush()
            db.execute("attach ? as part", (tmp.name,))
            for table in tables:
                db.execute(f"insert or ignore into main.{table} select * from part.{table}")
            db.execute(
                "update main.sqlite_sequence set seq = max(seq, coalesce((select p.seq from "
                "part.sqlite_sequence p where p.name = main.sqlite_sequence.name), 0))"
            )
            db.commit()
            db.execute("detach part")
    db.close()


def restore(state: Path, data: Path) -> None:
    database = data / "ideeprl.sqlite3"
    if not database.exists():
        merge(state, database)
    advisors = state / "advisors"
    for f in advisors.rglob("*"):
        target = data / f.relative_to(advisors)
        if f.is_file() and not target.exists():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(f, target)


if __name__ == "__main__":
    command, a, b = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
    {"save": save, "restore": restore, "open": merge}[command](a, b)
