"""hardening: ids never reused (SQLite AUTOINCREMENT), replay memory kept on request

Revision ID: 0003
Revises: 0002_reset_seed
Create Date: 2026-12-01 20:40:00

SQLite otherwise gives a new row the largest id plus one, so deleting the newest study
hands its id to the next one. PostgreSQL's sequences never go back; nothing to do there.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | None = "0002_reset_seed"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLES = ("studies", "participants", "sessions")


def upgrade() -> None:
    with op.batch_alter_table("sessions") as batch_op:
        batch_op.add_column(sa.Column("keep_replay_memory", sa.Boolean(), nullable=True))
    if op.get_bind().dialect.name == "sqlite":
        for table in TABLES:
            with op.batch_alter_table(
                table, recreate="always", table_kwargs={"sqlite_autoincrement": True}
            ):
                pass


def downgrade() -> None:
    with op.batch_alter_table("sessions") as batch_op:
        batch_op.drop_column("keep_replay_memory")
