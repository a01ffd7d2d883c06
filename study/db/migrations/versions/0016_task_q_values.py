"""Steps of tasks other than the sorting robot's: any number of Q-values

Revision ID: 0016
Revises: 0015

A run names its task (`RunSpec.task`). A task with four actions keeps its Q-values in the
four named columns, as every step did before; one with another number of actions leaves
them empty and lists its Q-values in `steps.q_values` (JSON).
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0016"
down_revision: str | None = "0015"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

NAMED = ("q_grab", "q_move_right", "q_move_left", "q_drop")


def upgrade() -> None:
    with op.batch_alter_table("steps") as batch:
        batch.add_column(sa.Column("q_values", sa.Text(), nullable=True))
        for name in NAMED:
            batch.alter_column(name, existing_type=sa.Float(), nullable=True)


def downgrade() -> None:
    with op.batch_alter_table("steps") as batch:
        for name in NAMED:
            batch.alter_column(name, existing_type=sa.Float(), nullable=False)
        batch.drop_column("q_values")
