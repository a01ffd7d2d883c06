"""sessions.scenario: the scenario options (reward scheme, realism rates)

Revision ID: 0004
Revises: 0001
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # Sessions stored before this revision ran the paper's scenario: {} reads as its defaults.
    with op.batch_alter_table("sessions") as batch:
        batch.add_column(sa.Column("scenario", sa.JSON(), nullable=False, server_default="{}"))


def downgrade() -> None:
    with op.batch_alter_table("sessions") as batch:
        batch.drop_column("scenario")
