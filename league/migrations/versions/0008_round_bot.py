"""Round bots: which of the league's bots fills an event's head-to-model grids.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-01
"""

from __future__ import annotations

from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None

# Plain ALTER TABLE, as in 0007: a batch copy of ``events`` would delete its entries.
ADD_ROUND_BOT = (
    "ALTER TABLE events ADD COLUMN round_bot VARCHAR(16) DEFAULT 'pursuit' NOT NULL"
    " CONSTRAINT ck_events_round_bot CHECK (round_bot IN ('pursuit', 'racer'))"
)


def upgrade() -> None:
    """Add ``events.round_bot``; existing events keep the bot they had, ``pursuit``."""
    op.execute(ADD_ROUND_BOT)


def downgrade() -> None:
    """Drop ``events.round_bot`` (an older league fills every grid with ``pursuit``)."""
    op.execute("ALTER TABLE events DROP COLUMN round_bot")
