"""fitted_advisors: advisor models fitted to a study's people (`learner.fitted`)

Revision ID: 0011
Revises: 0010

`ideeprl fit` stores each model with the sessions it was fitted from, so that deleting
any of them (a participant's data) deletes the model too.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0011"
down_revision: str | None = "0010"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "fitted_advisors",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("model", sa.JSON(), nullable=False),
        sa.Column("session_ids", sa.JSON(), nullable=False),
        sa.ForeignKeyConstraint(["study_id"], ["studies.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_fitted_advisors_study_id", "fitted_advisors", ["study_id"])


def downgrade() -> None:
    op.drop_index("ix_fitted_advisors_study_id", table_name="fitted_advisors")
    op.drop_table("fitted_advisors")
