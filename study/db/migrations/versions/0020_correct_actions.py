"""advice.correct_actions, feedback.correct_actions: every action as right as the correct one

Revision ID: 0020
Revises: 0019

Where a task has several right actions at a step (the grid world's moves that bring the
agent equally near the goal), `correct_action` holds the one the oracle advises and
`correct_actions` all of them (`tasks.Task.correct_actions`): advice naming any of them is
accurate, and a rating is right when it calls one of them good or another action bad. A
JSON list of action indices; NULL where the task cannot say, and in rows stored before this
revision (their accuracy reads `correct_action` alone).
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0020"
down_revision: str | None = "0019"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    for table in ("advice", "feedback"):
        with op.batch_alter_table(table) as batch:
            batch.add_column(sa.Column("correct_actions", sa.JSON(), nullable=True))


def downgrade() -> None:
    for table in ("advice", "feedback"):
        with op.batch_alter_table(table) as batch:
            batch.drop_column("correct_actions")
