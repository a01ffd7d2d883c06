"""Replays: each step's observation hash, a session's source and stream, replayed advice

Revision ID: 0012
Revises: 0011

`ideeprl replay` re-runs a recorded session (SPEC section 5, "Replay"). An unchanged replay
is checked step by step against its original, observations included:
`steps.observation_hash` (NULL in rows stored before). A replay names its source
(`sessions.replay_of`, deleted with it: the advice is a person's data) and keeps a copy of
the stream it feeds (`sessions.replay_stream`).
Each replayed advice records whether it met the image its advisor saw
(`advice.same_observation`); a request beyond the recorded stream is an advice row without
an action, so `advice.action` becomes nullable (no existing row changes).
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0012"
down_revision: str | None = "0011"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("steps") as batch:
        batch.add_column(sa.Column("observation_hash", sa.String(16), nullable=True))
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("replay_of", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("replay_stream", sa.JSON(), nullable=True))
        batch.create_foreign_key(
            "fk_sessions_replay_of", "sessions", ["replay_of"], ["id"], ondelete="CASCADE"
        )
        batch.create_index("ix_sessions_replay_of", ["replay_of"])
    with op.batch_alter_table("advice") as batch:
        batch.add_column(sa.Column("same_observation", sa.Boolean(), nullable=True))
        batch.alter_column("action", existing_type=sa.Integer(), nullable=True)


def downgrade() -> None:
    with op.batch_alter_table("advice") as batch:
        batch.alter_column("action", existing_type=sa.Integer(), nullable=False)
        batch.drop_column("same_observation")
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_index("ix_sessions_replay_of")
        batch.drop_constraint("fk_sessions_replay_of", type_="foreignkey")
        batch.drop_column("replay_stream")
        batch.drop_column("replay_of")
    with op.batch_alter_table("steps") as batch:
        batch.drop_column("observation_hash")
