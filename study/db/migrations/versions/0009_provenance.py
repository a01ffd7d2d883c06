"""sessions.provenance: where each run was computed (code version, CPU kind, torch, numerics)

Revision ID: 0009
Revises: 0008

A list, one entry each time a worker starts or resumes the run; sessions stored before
this revision have none (what computed them was not recorded).
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0009"
down_revision: str | None = "0008"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("provenance", sa.JSON(), nullable=True))
    op.execute("UPDATE sessions SET provenance = '[]'")
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.alter_column("provenance", existing_type=sa.JSON(), nullable=False)


def downgrade() -> None:
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_column("provenance")
