"""A real study server on loopback, in its own process, for the API tests."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

from tests.server.contract import checked_client

ROOT = Path(__file__).absolute().parents[2]
API_KEY = "test-researcher-key"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def fresh_database(tmp: Path) -> Iterator[str]:
    """A SQLite file in `tmp`, or a new database on the PostgreSQL server that
    `DATABASE_URL` points at (dropped afterwards)."""
    base = os.environ.get("DATABASE_URL")
    if not base:
        yield f"sqlite:///{tmp / 'study.sqlite3'}"
        return
    url = make_url(base.replace("postgresql://", "postgresql+psycopg://", 1))
    name = f"ideeprl_test_{uuid.uuid4().hex[:10]}"
    admin = create_engine(url, isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield url.set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


class LiveServer:
    """`ideeprl serve` on a free port; restartable on the same data (for crash tests)."""

    def __init__(self, data_dir: Path, database_url: str, **settings: Any) -> None:
        self.data_dir = data_dir
        self.database_url = database_url
        self.settings = settings
        self.process: subprocess.Popen[bytes] | None = None
        self.port = 0
        self.log = data_dir / "server.log"

    @property
    def entry(self) -> list[str]:
        """The command that runs `ideeprl` (a test may wrap it to watch the process)."""
        return [sys.executable, "-m", "cli"]

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> LiveServer:
        self.port = self.port or free_port()
        env = {
            **os.environ,
            "IDEEPRL_DATABASE_URL": self.database_url,
            "IDEEPRL_API_KEY": API_KEY,
            "IDEEPRL_DATA_DIR": str(self.data_dir),
            "PYTHONPATH": os.pathsep.join(filter(None, [os.environ.get("PYTHONPATH"), str(ROOT)])),
            **{f"IDEEPRL_{k.upper()}": str(v) for k, v in self.settings.items()},
        }
        env.pop("DATABASE_URL", None)
        with self.log.open("ab") as log:
            self.process = subprocess.Popen(
                [*self.entry, "serve", "--port", str(self.port), "--log-level", "warning"],
                cwd=ROOT,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            assert self.process.poll() is None, f"server exited:\n{self.log.read_text()}"
            try:
                if httpx.get(f"{self.url}/api/health", timeout=1).status_code == 200:
                    return self
            except httpx.HTTPError:
                time.sleep(0.1)
        raise AssertionError(f"server did not start:\n{self.log.read_text()}")

    def stop(self, kill: bool = False) -> None:
        if self.process is None:
            return
        self.process.send_signal(signal.SIGKILL if kill else signal.SIGINT)
        try:
            self.process.wait(90)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.process = None

    def client(self, key: str | None = API_KEY, token: str | None = None) -> httpx.Client:
        headers = {}
        if key is not None:
            headers["X-API-Key"] = key
        if token is not None:
            headers["Authorization"] = f"Bearer {token}"
        return checked_client(base_url=self.url, headers=headers, timeout=120)


@contextmanager
def serving(data_dir: Path, **settings: Any) -> Iterator[LiveServer]:
    """A started `LiveServer` on a fresh database in `data_dir`, stopped afterwards."""
    with fresh_database(data_dir) as url:
        live = LiveServer(data_dir, url, **settings).start()
        try:
            yield live
        finally:
            live.stop()
