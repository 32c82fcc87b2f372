"""Racers and their uploaded models.

Revision ID: 0001
Revises:
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

UTC_TIME = sa.DateTime(timezone=True)


def upgrade() -> None:
    """Create ``racers`` and ``models``."""
    op.create_table(
        "racers",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("alias", sa.String(length=32), nullable=False),
        sa.Column("role", sa.String(length=16), nullable=False),
        sa.Column("token_hash", sa.String(length=64), nullable=False),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.CheckConstraint("role IN ('racer', 'admin')", name=op.f("ck_racers_role")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_racers")),
        sa.UniqueConstraint("alias", name=op.f("uq_racers_alias")),
        sa.UniqueConstraint("token_hash", name=op.f("uq_racers_token_hash")),
    )
    op.create_table(
        "models",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("owner_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("size", sa.Integer(), nullable=False),
        sa.Column("info", sa.JSON(), nullable=False),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.ForeignKeyConstraint(
            ["owner_id"],
            ["racers.id"],
            name=op.f("fk_models_owner_id_racers"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_models")),
        sa.UniqueConstraint("owner_id", "sha256", name=op.f("uq_models_owner_id")),
    )
    op.create_index(op.f("ix_models_owner_id"), "models", ["owner_id"])
    op.create_index(op.f("ix_models_sha256"), "models", ["sha256"])


def downgrade() -> None:
    """Drop ``models`` and ``racers``."""
    op.drop_index(op.f("ix_models_sha256"), table_name="models")
    op.drop_index(op.f("ix_models_owner_id"), table_name="models")
    op.drop_table("models")
    op.drop_table("racers")
