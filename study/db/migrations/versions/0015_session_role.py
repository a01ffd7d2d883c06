"""Sessions' role: `advisor` marks the advisors a batch trains for the agent method

Revision ID: 0015
Revises: 0014

`ideeprl batch` trains an advisor for its `agent` runs and, when one fails its check, the
next seed again: every such attempt is an advisor, passed or failed, used or not, never one
of the compared agents. `sessions.role` says so (NULL: a compared agent, a person's session).
The batches before this revision labelled their advisors `LABEL advisor` and gave them the
advisor seeds (`runs.batch.spec.ADVISOR_SEED_OFFSET` and up): those are marked here.
"""

import json
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0015"
down_revision: str | None = "0014"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

ADVISOR_SEED_OFFSET = 100_000  # (runs.batch.spec's, as it was when this revision was written)


def upgrade() -> None:
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("role", sa.String(20), nullable=True))
    connection = op.get_bind()
    query = sa.text("SELECT id, label, run FROM sessions WHERE label LIKE :label")
    rows = connection.execute(query, {"label": "% advisor"})
    marked = []
    for session_id, label, run in rows:
        run = json.loads(run) if isinstance(run, str) else run
        if (
            label.endswith(" advisor")
            and run.get("method") == "autonomous"
            and int(run.get("seed", 0)) >= ADVISOR_SEED_OFFSET
        ):
            marked.append(session_id)
    for session_id in marked:
        connection.execute(
            sa.text("UPDATE sessions SET role = 'advisor' WHERE id = :id"), {"id": session_id}
        )


def downgrade() -> None:
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_column("role")
