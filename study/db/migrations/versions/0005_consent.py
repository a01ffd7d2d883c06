"""consent on the server: texts versions, consent/decline times, browser decision time

Revision ID: 0005
Revises: 0003
Create Date: 2026-12-01 20:30:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "study_texts",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("content_hash", sa.String(length=64), nullable=False),
        sa.Column("texts", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["study_id"], ["studies.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("study_id", "content_hash"),
        sa.UniqueConstraint("study_id", "version"),
    )
    with op.batch_alter_table(  # a rebuilt table keeps AUTOINCREMENT (0003)
        "sessions", schema=None, table_kwargs={"sqlite_autoincrement": True}
    ) as batch_op:
        batch_op.add_column(sa.Column("texts_version_id", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("consented_at", sa.DateTime(timezone=True), nullable=True))
        batch_op.add_column(sa.Column("declined_at", sa.DateTime(timezone=True), nullable=True))
        batch_op.add_column(
            sa.Column("induction_done_at", sa.DateTime(timezone=True), nullable=True)
        )
        batch_op.create_foreign_key(
            "fk_sessions_texts_version_id",
            "study_texts",
            ["texts_version_id"],
            ["id"],
            ondelete="SET NULL",
        )
    with op.batch_alter_table("advice", schema=None) as batch_op:
        batch_op.add_column(sa.Column("decision_time_s", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("advice", schema=None) as batch_op:
        batch_op.drop_column("decision_time_s")
    with op.batch_alter_table(
        "sessions", schema=None, table_kwargs={"sqlite_autoincrement": True}
    ) as batch_op:
        batch_op.drop_constraint("fk_sessions_texts_version_id", type_="foreignkey")
        batch_op.drop_column("induction_done_at")
        batch_op.drop_column("declined_at")
        batch_op.drop_column("consented_at")
        batch_op.drop_column("texts_version_id")
    op.drop_table("study_texts")
