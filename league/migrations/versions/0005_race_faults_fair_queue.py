"""Race faults and a fair queue: a car's DNF reason, suspended entries, when the queue last
served each racer and each event's rounds.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add ``race_cars.dnf_reason``, ``entries.suspended_at`` / ``suspension``,
    ``racers.queue_served_at`` and ``events.rounds_served_at`` (all null: nobody suspended,
    nobody served yet)."""
    with op.batch_alter_table("race_cars") as batch:
        batch.add_column(sa.Column("dnf_reason", sa.Text(), nullable=True))
    with op.batch_alter_table("entries") as batch:
        batch.add_column(sa.Column("suspended_at", sa.DateTime(timezone=True), nullable=True))
        batch.add_column(sa.Column("suspension", sa.Text(), nullable=True))
    with op.batch_alter_table("racers") as batch:
        batch.add_column(sa.Column("queue_served_at", sa.DateTime(timezone=True), nullable=True))
    with op.batch_alter_table("events") as batch:
        batch.add_column(sa.Column("rounds_served_at", sa.DateTime(timezone=True), nullable=True))


def downgrade() -> None:
    """Drop the five columns again."""
    with op.batch_alter_table("events") as batch:
        batch.drop_column("rounds_served_at")
    with op.batch_alter_table("racers") as batch:
        batch.drop_column("queue_served_at")
    with op.batch_alter_table("entries") as batch:
        batch.drop_column("suspension")
        batch.drop_column("suspended_at")
    with op.batch_alter_table("race_cars") as batch:
        batch.drop_column("dnf_reason")
