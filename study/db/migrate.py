"""Bring any database up to the current schema with Alembic (start-up and the batch CLI),
backing it up first when it holds data at an older revision."""

from __future__ import annotations

import logging
from datetime import UTC, datetime
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Engine, inspect

MIGRATIONS = Path(__file__).with_name("migrations")
BACKUPS = "backups"
"""The data folder's sub-folder for the automatic backups taken before a migration."""
log = logging.getLogger(__name__)


def alembic_config(engine: Engine) -> Config:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    config.attributes["engine"] = engine
    return config


def default_backups(engine: Engine) -> Path | None:
    """Beside a SQLite file (the data folder, by default); None for a server database."""
    database = engine.url.database
    if engine.url.get_backend_name() == "sqlite" and database and database != ":memory:":
        return Path(database).parent / BACKUPS
    return None


def upgrade(engine: Engine, backups: Path | None = None) -> Path | None:
    """Apply every migration not yet applied; a fresh database gets the whole schema.

    A database with tables at an older revision is first copied (as of one instant) into
    `backups/pre-migration-REVISION-TIME/` (default: `default_backups`), so a migration
    that goes wrong never costs a study its data; returns that folder, or None."""
    config = alembic_config(engine)
    head = ScriptDirectory.from_config(config).get_current_head()
    with engine.connect() as connection:
        current = MigrationContext.configure(connection).get_current_revision()
        has_tables = bool(inspect(connection).get_table_names())
    saved = None
    if has_tables and current != head:
        folder = backups or default_backups(engine)
        if folder is None:
            log.warning(
                "migrating from %s to %s without a backup (no folder for it)", current, head
            )
        else:
            from study.db.backup import backup_database

            stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S%fZ")
            saved = folder / f"pre-migration-{current or 'unversioned'}-{stamp}"
            backup_database(engine, saved)
            log.warning(
                "database at %s backed up to %s before migrating to %s", current, saved, head
            )
    command.upgrade(config, "head")
    return saved
