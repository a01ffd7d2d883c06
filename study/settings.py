"""The server's one settings object: the only place that reads the environment.

Values come from environment variables prefixed `IDEEPRL_` (or a `.env` file in the
working directory); `DATABASE_URL` is accepted without the prefix because CI and most
hosting set that plain name.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path

from pydantic import AliasChoices, Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

API_KEY_FILE = "api_key"


class Settings(BaseSettings):
    """Everything the web process and its session workers need to know about this install."""

    model_config = SettingsConfigDict(env_prefix="IDEEPRL_", env_file=".env", extra="ignore")

    data_dir: Path = Path("study_data")
    """Where the database (by default), checkpoints, exports and the generated key live."""

    database_url: str | None = Field(
        default=None, validation_alias=AliasChoices("IDEEPRL_DATABASE_URL", "DATABASE_URL")
    )
    """Any SQLAlchemy URL; default: SQLite file `ideeprl.sqlite3` in `data_dir`."""

    api_key: str | None = None
    """Researcher key (header `X-API-Key`). Unset: generated once and kept in `data_dir`."""

    host: str = "127.0.0.1"
    """Interface the HTTP server listens on: `0.0.0.0` (or `::`) serves other computers."""

    port: int = Field(default=8000, ge=0, le=65535)
    """HTTP port: the one port of the whole platform (API, pages, dashboard, 3-D view)."""

    public_url: str | None = None
    """Base URL participants reach the server at, e.g. `https://study.example.org` behind
    a reverse proxy: the participant links use it. Default `http://host:port`."""

    idle_limit_s: float = Field(default=1800.0, gt=0)
    """Seconds without advice while advice is wanted before a human session is abandoned."""

    checkpoint_every_episodes: int = Field(default=10, ge=1)
    """Training episodes between periodic checkpoints (also taken at pause and stop)."""

    flush_every_steps: int = Field(default=500, ge=1)
    """Step records a worker buffers before one batched insert (also flushed per episode)."""

    heartbeat_s: float = Field(default=5.0, gt=0)
    """How often a worker marks itself alive in the database."""

    stale_after_s: float = Field(default=60.0, gt=0)
    """A running session whose worker has not marked itself alive for this long is dead."""

    worker_threads: int = Field(default=1, ge=1)
    """torch threads of a session whose run leaves them open (`config.torch_threads` 0), pinned
    in the run when it is created; several workers share the machine's cores."""

    pretrain_on_create: bool = True
    """A human session made by hand (the REST API, the dashboard's new participant) starts
    its random practice when it is made, so a participant who opens their link at once and
    clicks straight through does not wait for it (an online study's arrivals get practised
    sessions from its pools); `?pretrain=false` leaves one to its link. Each practised
    session holds a worker process while it waits for its participant."""
    pretrain_ahead_limit: int = Field(default=8, ge=0, le=1000)
    """Human sessions that may hold a worker at once while they wait for their participant
    (practising, or practised); a session made beyond them practises when its link is
    opened, so a script making many sessions does not start a process for each."""

    trainer_nice: int = Field(default=10, ge=0, le=19)
    """Niceness of machine-advised workers, and of human sessions once their advice is
    over, so training never slows people's requests."""

    trainer_idle: bool = True
    """Those workers also run in Linux's SCHED_IDLE class: only when no participant's
    worker, the web process or anything else ordinary wants the CPU (nice 10 alone still
    gave two trainers a core's share under a crowd of 30)."""

    max_trainers: int = Field(default=0, ge=0)
    """Human sessions that train at once after their advice; the others wait in a queue
    (shown as status `queued`, with `queue_place`; stored as `running`). 0: the number of
    cores."""

    training_population: int = Field(default=0, ge=0)
    """Finished human sessions of one learner configuration that train together in one
    trainer slot, as a population (one worker process; `runs.worker.population`), at
    most. 0: the batch's default rule (`default_population`); 1: each alone."""

    viser_host: str = "127.0.0.1"
    """Interface viser (the 3-D view's server) listens on. Browsers never reach it directly:
    the app relays it under `/viewer/` on its own port, so keep it on loopback."""

    viser_port: int = Field(default=0, ge=0, le=65535)
    """viser's port on `viser_host`; 0 picks a free one, and a taken one is skipped upwards."""

    viewer_public_url: str | None = None
    """Base URL browsers load the 3-D view from; default `/viewer/` on the page's own origin.
    Only for unusual setups, e.g. the tests, which load it from another host name of the
    same server so that Chromium renders it in a process of its own."""

    viewer_playback_speed: float = Field(default=1.0, gt=0)
    """How fast the 3-D view replays the robot's motion; 1 is real time."""

    playback_limit: int = Field(default=2, ge=1, le=32)
    """Episode playbacks open at once in the dashboard (each reruns its episode in a process
    of its own); more get 429 until one is closed or idle."""

    playback_idle_s: float = Field(default=120.0, gt=0)
    """A playback whose page has sent nothing for this long is closed (the page pings while
    it is open, and says when it closes)."""

    max_request_bytes: int = Field(default=1_048_576, ge=1024)
    """Largest request body accepted (bytes); larger ones get 413 before they are read."""

    forwarded_allow_ips: str = "127.0.0.1"
    """Addresses of the reverse proxy (comma-separated, `*` for any): only requests from
    them have their client address taken from `X-Forwarded-For` (uvicorn's rule); the
    study links' per-address limit counts that address."""

    join_per_address_per_minute: int = Field(default=30, ge=1)
    """Arrivals at study links one client address may make in a minute (429 beyond)."""

    join_per_place_per_minute: int = Field(default=6, ge=1)
    """Arrivals at one study's link per minute, per place of its capacity (429 beyond)."""
    pool_limit: int = Field(default=8, ge=0, le=1000)
    """Pretrained sessions waiting for arrivals, all online studies' pools together: each
    is a worker process (about 110-130 MB proportional memory, its torch shared with the
    others) that spent its random practice once; 0 turns the pools off."""
    pool_practising: int = Field(default=0, ge=0, le=1000)
    """Pooled sessions practising at once (each takes a core for several seconds); the
    others wait their turn, so participants advising keep the rest of the machine. 0: one
    fewer than the cores, at least one."""
    pool_every_s: float = Field(default=2.0, gt=0, le=3600)
    """How often the pools are topped up."""

    dashboard_login_s: float = Field(default=8 * 3600.0, gt=0)
    """How long a dashboard login lasts; logging out ends it at once."""

    ray_address: str | None = None
    """A Ray cluster (`ray://head:10001`, or `auto` on a node of it) that trains the human
    sessions whose advice is over, in place of this machine's trainer slots
    (`server.live.cluster`); unset: they train here. Needs a database every node reaches
    (PostgreSQL) and `storage_root`."""

    storage_root: Path | None = None
    """The folder every node of the Ray cluster sees, where checkpoints go (a node may
    mount it elsewhere: `IDEEPRL_STORAGE_ROOT` in its `ray start`'s environment); default
    `data_dir` (then it must be the shared folder). Without `ray_address` checkpoints stay
    in `data_dir`."""

    keep_replay_memory: bool = False
    """Keep the replay memory in a finished session's final checkpoint (a session's own
    `keep_replay_memory` wins). Without it the checkpoint holds the network and what an
    advisor needs: a few MB instead of the whole memory (about 250 MB at paper scale)."""

    @field_validator("database_url")
    @classmethod
    def _driver(cls, url: str | None) -> str | None:
        # psycopg (v3) is the PostgreSQL driver we ship; a bare postgresql:// means psycopg2.
        if url is not None and url.startswith(("postgresql://", "postgres://")):
            return "postgresql+psycopg://" + url.split("://", 1)[1]
        return url

    @property
    def db_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{self.data_dir / 'ideeprl.sqlite3'}"

    @property
    def checkpoint_root(self) -> Path:
        """Where sessions' checkpoints lie (`checkpoints/session-ID/`): with a Ray cluster
        the storage root its nodes share (`storage_root`, else `data_dir`), else `data_dir`.
        Workers write there; deletion removes them there; `session:ID` advisors read them
        there."""
        if self.ray_address is None:
            return self.data_dir
        return Path(os.path.abspath(self.storage_root or self.data_dir))

    @property
    def shared_root(self) -> Path | None:
        """The storage root a Ray cluster's nodes share, which stored checkpoint paths are
        relative to (each node may mount it elsewhere); None: one machine, whose stored
        paths are absolute."""
        return self.checkpoint_root if self.ray_address is not None else None

    @property
    def export_dir(self) -> Path:
        return self.data_dir / "exports"

    @property
    def base_url(self) -> str:
        return (self.public_url or f"http://{self.host}:{self.port}").rstrip("/")

    def ensure_api_key(self) -> tuple[str, bool]:
        """The researcher key, generating and saving one on first use; True if new."""
        if self.api_key:
            return self.api_key, False
        path = self.data_dir / API_KEY_FILE
        if path.exists():
            self.api_key = path.read_text().strip()
            return self.api_key, False
        self.data_dir.mkdir(parents=True, exist_ok=True)
        key = secrets.token_urlsafe(24)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(key + "\n")
        self.api_key = key
        return key, True
