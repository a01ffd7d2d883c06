"""steps.outcome: what each step did to the objects (placed, misplaced, lost, nothing)

Revision ID: 0010
Revises: 0009

Rescoring a run under another reward scheme keeps the rewards of placements only, and the
reward alone cannot say which steps placed an object (an episode that ends because its
last object was knocked off; under authors-autonomous a 119th step's cost of -1, a wrong
placement's reward). Rows stored before this revision hold NULL until their episodes are
replayed from their reset seeds (`ideeprl outcomes`, `study.services.outcomes`).
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010"
down_revision: str | None = "0009"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("steps") as batch:
        batch.add_column(sa.Column("outcome", sa.String(10), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("steps") as batch:
        batch.drop_column("outcome")
