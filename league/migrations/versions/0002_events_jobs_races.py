"""Events, entries, the job queue, races with per-car results, and ratings.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

UTC_TIME = sa.DateTime(timezone=True)


def _id() -> sa.Column:
    return sa.Column("id", sa.Integer(), nullable=False)


def _fk(table: str, column: str, target: str, ondelete: str = "CASCADE") -> sa.ForeignKeyConstraint:
    return sa.ForeignKeyConstraint(
        [column], [f"{target}.id"], name=op.f(f"fk_{table}_{column}_{target}"), ondelete=ondelete
    )


def _pk(table: str) -> sa.PrimaryKeyConstraint:
    return sa.PrimaryKeyConstraint("id", name=op.f(f"pk_{table}"))


def upgrade() -> None:
    """Create the event, entry, job, race, race-car and rating tables."""
    op.create_table(
        "events",
        _id(),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("race_type", sa.String(length=32), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("direction", sa.String(length=8), nullable=False),
        sa.Column("ranking_metric", sa.String(length=16), nullable=False),
        sa.Column("ruleset", sa.JSON(), nullable=False),
        sa.Column("ruleset_hash", sa.String(length=64), nullable=False),
        sa.Column("seeds", sa.JSON(), nullable=False),
        sa.Column("opens_at", UTC_TIME, nullable=False),
        sa.Column("closes_at", UTC_TIME, nullable=True),
        sa.Column("round_interval_s", sa.Integer(), nullable=True),
        sa.Column("next_round_at", UTC_TIME, nullable=True),
        sa.Column("results_version", sa.Integer(), nullable=False),
        sa.Column("created_by", sa.Integer(), nullable=True),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.CheckConstraint("direction IN ('ccw', 'cw')", name=op.f("ck_events_direction")),
        sa.CheckConstraint(
            "race_type IN ('time_trial', 'object_avoidance', 'head_to_bot', 'head_to_model')",
            name=op.f("ck_events_race_type"),
        ),
        sa.CheckConstraint(
            "ranking_metric IN ('total', 'best', 'average')",
            name=op.f("ck_events_ranking_metric"),
        ),
        _fk("events", "created_by", "racers", "SET NULL"),
        _pk("events"),
    )
    op.create_table(
        "entries",
        _id(),
        sa.Column("event_id", sa.Integer(), nullable=False),
        sa.Column("model_id", sa.Integer(), nullable=False),
        sa.Column("racer_id", sa.Integer(), nullable=False),
        sa.Column("created_at", UTC_TIME, nullable=False),
        _fk("entries", "event_id", "events"),
        _fk("entries", "model_id", "models"),
        _fk("entries", "racer_id", "racers"),
        _pk("entries"),
        sa.UniqueConstraint("event_id", "model_id", name=op.f("uq_entries_event_id")),
    )
    for column in ("event_id", "model_id", "racer_id"):
        op.create_index(op.f(f"ix_entries_{column}"), "entries", [column])
    op.create_table(
        "ratings",
        _id(),
        sa.Column("event_id", sa.Integer(), nullable=False),
        sa.Column("model_id", sa.Integer(), nullable=False),
        sa.Column("mu", sa.Float(), nullable=False),
        sa.Column("sigma", sa.Float(), nullable=False),
        sa.Column("races", sa.Integer(), nullable=False),
        sa.Column("updated_at", UTC_TIME, nullable=False),
        _fk("ratings", "event_id", "events"),
        _fk("ratings", "model_id", "models"),
        _pk("ratings"),
        sa.UniqueConstraint("event_id", "model_id", name=op.f("uq_ratings_event_id")),
    )
    op.create_index(op.f("ix_ratings_event_id"), "ratings", ["event_id"])
    op.create_table(
        "jobs",
        _id(),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("event_id", sa.Integer(), nullable=False),
        sa.Column("entry_id", sa.Integer(), nullable=True),
        sa.Column("round", sa.Integer(), nullable=True),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("max_attempts", sa.Integer(), nullable=False),
        sa.Column("lease_owner", sa.String(length=128), nullable=True),
        sa.Column("lease_expires_at", UTC_TIME, nullable=True),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.Column("updated_at", UTC_TIME, nullable=False),
        sa.CheckConstraint("kind IN ('evaluation', 'round')", name=op.f("ck_jobs_kind")),
        sa.CheckConstraint(
            "status IN ('queued', 'running', 'done', 'failed')", name=op.f("ck_jobs_status")
        ),
        _fk("jobs", "entry_id", "entries"),
        _fk("jobs", "event_id", "events"),
        _pk("jobs"),
        sa.UniqueConstraint("entry_id", "seed", name=op.f("uq_jobs_entry_id")),
        sa.UniqueConstraint("event_id", "round", "seed", name="uq_jobs_event_round_seed"),
    )
    op.create_index(op.f("ix_jobs_event_id"), "jobs", ["event_id"])
    op.create_index("ix_jobs_status_lease", "jobs", ["status", "lease_expires_at"])
    op.create_table(
        "races",
        _id(),
        sa.Column("event_id", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=True),
        sa.Column("ruleset_hash", sa.String(length=64), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("config", sa.JSON(), nullable=False),
        sa.Column("summary", sa.JSON(), nullable=False),
        sa.Column("trace_sha256", sa.String(length=64), nullable=True),
        sa.Column("created_at", UTC_TIME, nullable=False),
        _fk("races", "event_id", "events"),
        _fk("races", "job_id", "jobs", "SET NULL"),
        _pk("races"),
        sa.UniqueConstraint("job_id", name=op.f("uq_races_job_id")),
    )
    op.create_index(op.f("ix_races_event_id"), "races", ["event_id"])
    op.create_table(
        "race_cars",
        _id(),
        sa.Column("race_id", sa.Integer(), nullable=False),
        sa.Column("entry_id", sa.Integer(), nullable=True),
        sa.Column("model_id", sa.Integer(), nullable=True),
        sa.Column("car_name", sa.String(length=64), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("laps", sa.Integer(), nullable=False),
        sa.Column("lap_times_ms", sa.JSON(), nullable=False),
        sa.Column("best_ms", sa.Integer(), nullable=True),
        sa.Column("average_ms", sa.Integer(), nullable=True),
        sa.Column("total_ms", sa.Integer(), nullable=True),
        sa.Column("penalty_ms", sa.Integer(), nullable=False),
        sa.Column("off_track_count", sa.Integer(), nullable=False),
        sa.Column("crash_count", sa.Integer(), nullable=False),
        sa.Column("reset_count", sa.Integer(), nullable=False),
        sa.Column("distance_m", sa.Float(), nullable=False),
        sa.Column("finish_position", sa.Integer(), nullable=False),
        sa.CheckConstraint(
            "status IN ('finished', 'dnf', 'time_up')", name=op.f("ck_race_cars_status")
        ),
        _fk("race_cars", "entry_id", "entries"),
        _fk("race_cars", "model_id", "models"),
        _fk("race_cars", "race_id", "races"),
        _pk("race_cars"),
        sa.UniqueConstraint("race_id", "car_name", name=op.f("uq_race_cars_race_id")),
    )
    op.create_index(op.f("ix_race_cars_entry_id"), "race_cars", ["entry_id"])
    op.create_index(op.f("ix_race_cars_race_id"), "race_cars", ["race_id"])


def downgrade() -> None:
    """Drop the tables of this revision, dependents first."""
    for table in ("race_cars", "races", "jobs", "ratings", "entries", "events"):
        op.drop_table(table)
