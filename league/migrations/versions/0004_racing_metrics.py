"""Racing metrics on race results: overtakes, times overtaken, at-fault collisions, laps
led and the gap to the winner.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

COUNTS = ("overtakes", "times_overtaken", "at_fault_collisions", "laps_led")


def upgrade() -> None:
    """Add the four counts (0 for races stored before) and ``gap_to_winner_ms`` (null)."""
    with op.batch_alter_table("race_cars") as batch:
        for name in COUNTS:
            batch.add_column(sa.Column(name, sa.Integer(), nullable=False, server_default="0"))
        batch.add_column(sa.Column("gap_to_winner_ms", sa.Integer(), nullable=True))


def downgrade() -> None:
    """Drop the five columns again."""
    with op.batch_alter_table("race_cars") as batch:
        batch.drop_column("gap_to_winner_ms")
        for name in reversed(COUNTS):
            batch.drop_column(name)
