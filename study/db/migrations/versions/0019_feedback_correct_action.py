"""feedback.correct_action: the task's correct action beside each judgement

Revision ID: 0019
Revises: 0018

A rating is right when it calls the task's correct action at the rated step good, or
another action bad (`tasks.Task.correct`, as `advice.correct_action` holds it for
advice). The worker knows it when the step is rated; stored beside the judgement, the
report reads it as it reads the advice's. NULL where the task cannot say, and in rows
stored before this revision.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0019"
down_revision: str | None = "0018"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("feedback") as batch:
        batch.add_column(sa.Column("correct_action", sa.Integer(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("feedback") as batch:
        batch.drop_column("correct_action")
