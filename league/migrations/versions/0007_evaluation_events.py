"""Evaluation events: a racer's unlisted run of one model on a track of their choice.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-28
"""

from __future__ import annotations

from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None

# Plain ALTER TABLE on both SQLite and PostgreSQL: a batch "move and copy" of ``events``
# would drop the old table with foreign keys on, and so delete every entry, job and race.
ADD_KIND = (
    "ALTER TABLE events ADD COLUMN kind VARCHAR(16) DEFAULT 'league' NOT NULL"
    " CONSTRAINT ck_events_kind CHECK (kind IN ('league', 'evaluation'))"
)


def upgrade() -> None:
    """Add ``events.kind`` (``league`` or ``evaluation``); existing events are ``league``."""
    op.execute(ADD_KIND)


def downgrade() -> None:
    """Delete the evaluation events (their entries, jobs and races go with them: an older
    league would list them as its own), then drop ``events.kind`` and its check."""
    op.execute("DELETE FROM events WHERE kind = 'evaluation'")
    op.execute("ALTER TABLE events DROP COLUMN kind")
