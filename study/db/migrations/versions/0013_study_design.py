"""Online studies: a study's design and public link; a session's condition and outcome

Revision ID: 0013
Revises: 0012

A study may carry a design (`studies.design`: conditions, targets, capacity, alpha, panel
setting, check, questionnaire, outcome codes; NULL for a lab study, as are those already
stored), the key of its public link (`studies.join_key`, unguessable, unique) and the seed
of its block randomization (`studies.assignment_seed`). A session made through the link
records its condition (`sessions.condition`), whether it waits pretrained in its condition's
pool for an arrival (`sessions.pooled`; the study counts the sessions it made,
`studies.sessions_made`, for their seeds), whether it is a researcher's preview
(`sessions.preview`, kept out of exports and reports) and how the visit ended
(`sessions.outcome`: completed, declined, excluded, timed_out; with `sessions.outcome_at`).
Each arrival's assignment (`assignments`: condition, block, position, seed, time, the
early-ended place it refills) and the panel's ids of a participant (`panel_ids`, apart from
the sessions; deleted with the participant) are tables of their own.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0013"
down_revision: str | None = "0012"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("studies", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("design", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("join_key", sa.String(64), nullable=True))
        batch.add_column(sa.Column("assignment_seed", sa.Integer(), nullable=True))
        batch.add_column(
            sa.Column("sessions_made", sa.Integer(), nullable=False, server_default="0")
        )
        batch.create_unique_constraint("uq_studies_join_key", ["join_key"])
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("condition", sa.String(100), nullable=True))
        batch.add_column(
            sa.Column("preview", sa.Boolean(), nullable=False, server_default=sa.false())
        )
        batch.add_column(
            sa.Column("pooled", sa.Boolean(), nullable=False, server_default=sa.false())
        )
        batch.add_column(sa.Column("outcome", sa.String(20), nullable=True))
        batch.add_column(sa.Column("outcome_at", sa.DateTime(timezone=True), nullable=True))
    op.create_table(
        "assignments",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("session_id", sa.Integer(), nullable=False),
        sa.Column("condition", sa.String(100), nullable=False),
        sa.Column("block", sa.Integer(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("seed", sa.Integer(), nullable=False),
        sa.Column("refills", sa.Integer(), nullable=True),
        sa.Column("assigned_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["study_id"], ["studies.id"], ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["session_id"], ["sessions.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("session_id"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_assignments_study_id", "assignments", ["study_id"])
    op.create_table(
        "panel_ids",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("panel_id", sa.String(200), nullable=False),
        sa.Column("params", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["study_id"], ["studies.id"], ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["participant_id"], ["participants.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("participant_id"),
        sa.UniqueConstraint("study_id", "panel_id"),
        sqlite_autoincrement=True,
    )


def downgrade() -> None:
    op.drop_table("panel_ids")
    op.drop_index("ix_assignments_study_id", table_name="assignments")
    op.drop_table("assignments")
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_column("outcome_at")
        batch.drop_column("outcome")
        batch.drop_column("pooled")
        batch.drop_column("preview")
        batch.drop_column("condition")
    with op.batch_alter_table("studies", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_constraint("uq_studies_join_key", type_="unique")
        batch.drop_column("sessions_made")
        batch.drop_column("assignment_seed")
        batch.drop_column("join_key")
        batch.drop_column("design")
