"""Scheduler: head-to-head round lineups on jobs and the final standings snapshot on events.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add ``jobs.lineup``, ``events.final_standings`` and ``events.finalized_at``."""
    with op.batch_alter_table("jobs") as batch:
        batch.add_column(sa.Column("lineup", sa.JSON(), nullable=True))
    with op.batch_alter_table("events") as batch:
        batch.add_column(sa.Column("final_standings", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("finalized_at", sa.DateTime(timezone=True), nullable=True))


def downgrade() -> None:
    """Drop the three columns again."""
    with op.batch_alter_table("events") as batch:
        batch.drop_column("finalized_at")
        batch.drop_column("final_standings")
    with op.batch_alter_table("jobs") as batch:
        batch.drop_column("lineup")
