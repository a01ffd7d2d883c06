"""feedback: evaluative feedback's judgements (reward shaping, beside advice)

Revision ID: 0017
Revises: 0016

A run's feedback kind (`RunSpec.feedback`) is advice, as every session before, or
evaluative: the learner takes its own action and its evaluator judges it. Each judgement
is one row: the action judged, the judgement (NULL: no answer), what it added to the
reward the learner remembers, and its times. Deleted with its session.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0017"
down_revision: str | None = "0016"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "feedback",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("session_id", sa.Integer(), nullable=False),
        sa.Column("feedback_index", sa.Integer(), nullable=False),
        sa.Column("global_step", sa.Integer(), nullable=False),
        sa.Column("evaluator", sa.String(20), nullable=False),
        sa.Column("action", sa.Integer(), nullable=False),
        sa.Column("judgement", sa.Float(), nullable=True),
        sa.Column("shaping", sa.Float(), nullable=False),
        sa.Column("greedy_action", sa.Integer(), nullable=False),
        sa.Column("observation_hash", sa.String(16), nullable=False),
        sa.Column("response_time_s", sa.Float(), nullable=False),
        sa.Column("decision_time_s", sa.Float(), nullable=True),
        sa.Column("requested_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("answered_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["session_id"], ["sessions.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("session_id", "feedback_index"),
    )
    op.create_index("ix_feedback_session_step", "feedback", ["session_id", "global_step"])


def downgrade() -> None:
    op.drop_index("ix_feedback_session_step", table_name="feedback")
    op.drop_table("feedback")
