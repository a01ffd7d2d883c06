"""advice.correct_action: the task's correct action beside each advice

Revision ID: 0018
Revises: 0017

A participant's accuracy is the share of their advice that named the action the task
holds correct at that step (`tasks.Task.correct`: the sorting rule's, the grid world's
shortest path). The worker knows it when it asks; stored beside the advice, the report
reads it as it reads the advice. NULL where the task cannot say, and in rows stored before
this revision.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0018"
down_revision: str | None = "0017"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("advice") as batch:
        batch.add_column(sa.Column("correct_action", sa.Integer(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("advice") as batch:
        batch.drop_column("correct_action")
