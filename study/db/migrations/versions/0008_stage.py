"""steps.stage and episodes.stage: one word for a run's stage, and advice a source

Revision ID: 0008
Revises: 0007

The column `phase` of steps and episodes is `stage` (`pretrain` or `train`), the word the
code, the export and the pages use. A step row stored as `advice` (an advised pretraining
step) is stage `pretrain`: that it was advised is its `action_source` (`advisor`) and its
`advised_action`, which it keeps. The downgrade writes `advice` back for such steps.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    for table in ("steps", "episodes"):
        with op.batch_alter_table(table) as batch:
            batch.alter_column(
                "phase", new_column_name="stage", existing_type=sa.String(20), nullable=False
            )
    op.execute("UPDATE steps SET stage = 'pretrain' WHERE stage = 'advice'")


def downgrade() -> None:
    op.execute(
        "UPDATE steps SET stage = 'advice' WHERE stage = 'pretrain' AND action_source = 'advisor'"
    )
    for table in ("steps", "episodes"):
        with op.batch_alter_table(table) as batch:
            batch.alter_column(
                "stage", new_column_name="phase", existing_type=sa.String(20), nullable=False
            )
