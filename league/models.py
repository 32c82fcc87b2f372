"""The league's tables as SQLAlchemy 2 typed ORM classes.

Times are stored in UTC; per-car race times are whole milliseconds. Every change here needs
an Alembic revision in ``league/migrations/versions`` (a test compares the two).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from arena.config import RACE_TYPES
from league.bots import BOT_LEVELS

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

JOB_STATUSES = ("queued", "running", "done", "failed")
EVENT_KINDS = ("league", "evaluation")
RANKING_METRICS = ("total", "best", "average")


def utcnow() -> datetime:
    """The current time, timezone-aware UTC."""
    return datetime.now(UTC)


class UTCDateTime(TypeDecorator[datetime]):
    """A timestamp stored as UTC and always read back timezone-aware (SQLite drops zones)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value.astimezone(UTC)

    def process_result_value(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


class Base(DeclarativeBase):
    """Declarative base with a constraint naming convention (stable migration names)."""

    metadata = MetaData(naming_convention=NAMING)


def _in(column: str, values: tuple[str, ...]) -> str:
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


class Racer(Base):
    """A person (or team) with an alias; only the sha256 of their API token is stored.

    ``queue_served_at`` is when the queue last leased one of their evaluation jobs (the
    queue serves racers in turn, :mod:`league.jobs.queue`)."""

    __tablename__ = "racers"
    __table_args__ = (CheckConstraint(_in("role", ("racer", "admin")), name="role"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    alias: Mapped[str] = mapped_column(String(32), unique=True)
    role: Mapped[str] = mapped_column(String(16), default="racer")
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    queue_served_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)


class Model(Base):
    """An uploaded submission: a content-addressed file plus the validator's metadata."""

    __tablename__ = "models"
    __table_args__ = (UniqueConstraint("owner_id", "sha256"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("racers.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(64))
    sha256: Mapped[str] = mapped_column(String(64), index=True)
    size: Mapped[int] = mapped_column(Integer)
    info: Mapped[dict[str, Any]] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    owner: Mapped[Racer] = relationship(lazy="joined")


class Event(Base):
    """One leaderboard: a ruleset frozen at creation, a time window and evaluation seeds.

    ``final_standings`` is the snapshot the scheduler writes once the event has closed;
    ``rounds_served_at`` is when the queue last leased one of its round jobs (its rounds
    take their turn like a racer, :mod:`league.jobs.queue`). ``kind`` is ``league`` for the
    events admins create, ``evaluation`` for a racer's unlisted evaluation of one model
    (``/api/models/{id}/evaluations``): one entry, no other entries, no standings snapshot.
    ``round_bot`` is the bot (:mod:`league.bots`) that fills its head-to-model grids."""

    __tablename__ = "events"
    __table_args__ = (
        CheckConstraint(_in("race_type", RACE_TYPES), name="race_type"),
        CheckConstraint(_in("ranking_metric", RANKING_METRICS), name="ranking_metric"),
        CheckConstraint(_in("direction", ("ccw", "cw")), name="direction"),
        CheckConstraint(_in("kind", EVENT_KINDS), name="kind"),
        CheckConstraint(_in("round_bot", BOT_LEVELS), name="round_bot"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16), default="league", server_default="league")
    # events created before this column raced the pursuit bot (migration 0008)
    round_bot: Mapped[str] = mapped_column(String(16), server_default="pursuit")
    name: Mapped[str] = mapped_column(String(100))
    race_type: Mapped[str] = mapped_column(String(32))
    track: Mapped[str] = mapped_column(String(64))
    direction: Mapped[str] = mapped_column(String(8))
    ranking_metric: Mapped[str] = mapped_column(String(16))
    ruleset: Mapped[dict[str, Any]] = mapped_column(JSON)
    ruleset_hash: Mapped[str] = mapped_column(String(64))
    seeds: Mapped[list[int]] = mapped_column(JSON)
    opens_at: Mapped[datetime] = mapped_column(UTCDateTime)
    closes_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    round_interval_s: Mapped[int | None] = mapped_column(Integer, nullable=True)
    next_round_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    results_version: Mapped[int] = mapped_column(Integer, default=0)
    final_standings: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON, nullable=True)
    finalized_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    created_by: Mapped[int | None] = mapped_column(
        ForeignKey("racers.id", ondelete="SET NULL"), nullable=True
    )
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    rounds_served_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)

    def is_open(self, now: datetime) -> bool:
        """True while entries are accepted."""
        return self.opens_at <= now and (self.closes_at is None or now < self.closes_at)

    @property
    def status(self) -> str:
        """``upcoming``, ``open`` or ``closed``, as of now."""
        now = utcnow()
        return "upcoming" if now < self.opens_at else "open" if self.is_open(now) else "closed"


class Entry(Base):
    """A racer's model entered into an event (once per model and event).

    ``suspended_at`` and ``suspension`` (the message its owner reads) are set once the model
    broke too many of the event's races (:mod:`league.jobs.faults`); a suspended entry races
    no more in that event.
    """

    __tablename__ = "entries"
    __table_args__ = (UniqueConstraint("event_id", "model_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    event_id: Mapped[int] = mapped_column(ForeignKey("events.id", ondelete="CASCADE"), index=True)
    model_id: Mapped[int] = mapped_column(ForeignKey("models.id", ondelete="CASCADE"), index=True)
    racer_id: Mapped[int] = mapped_column(ForeignKey("racers.id", ondelete="CASCADE"), index=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    suspended_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    suspension: Mapped[str | None] = mapped_column(Text, nullable=True)


class Job(Base):
    """A unit of work for an evaluation worker, leased so that a dead worker's job returns.

    Evaluation jobs carry an entry and a seed, unique per (entry, seed); head-to-head round
    jobs (``entry_id`` null) carry a round number, unique per (event, round, seed), and a
    ``lineup``: the grid as ``[{"entry_id": 3}, {"bot": "pursuit"}, ...]``.
    """

    __tablename__ = "jobs"
    __table_args__ = (
        UniqueConstraint("entry_id", "seed"),
        UniqueConstraint("event_id", "round", "seed", name="uq_jobs_event_round_seed"),
        CheckConstraint(_in("status", JOB_STATUSES), name="status"),
        CheckConstraint(_in("kind", ("evaluation", "round")), name="kind"),
        Index("ix_jobs_status_lease", "status", "lease_expires_at"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16), default="evaluation")
    event_id: Mapped[int] = mapped_column(ForeignKey("events.id", ondelete="CASCADE"), index=True)
    entry_id: Mapped[int | None] = mapped_column(
        ForeignKey("entries.id", ondelete="CASCADE"), nullable=True
    )
    round: Mapped[int | None] = mapped_column(Integer, nullable=True)
    seed: Mapped[int] = mapped_column(BigInteger)
    lineup: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON, nullable=True)
    status: Mapped[str] = mapped_column(String(16), default="queued")
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    max_attempts: Mapped[int] = mapped_column(Integer, default=3)
    lease_owner: Mapped[str | None] = mapped_column(String(128), nullable=True)
    lease_expires_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)


class Race(Base):
    """One race run under an event's ruleset: its full config, summary and replay file."""

    __tablename__ = "races"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    event_id: Mapped[int] = mapped_column(ForeignKey("events.id", ondelete="CASCADE"), index=True)
    job_id: Mapped[int | None] = mapped_column(
        ForeignKey("jobs.id", ondelete="SET NULL"), nullable=True, unique=True
    )
    ruleset_hash: Mapped[str] = mapped_column(String(64))
    seed: Mapped[int] = mapped_column(BigInteger)
    config: Mapped[dict[str, Any]] = mapped_column(JSON)
    summary: Mapped[dict[str, Any]] = mapped_column(JSON)
    trace_sha256: Mapped[str | None] = mapped_column(String(64), nullable=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    cars: Mapped[list[RaceCar]] = relationship(
        back_populates="race", order_by="RaceCar.finish_position", cascade="all, delete-orphan"
    )


class RaceCar(Base):
    """One participant's result in one race (times in ms, penalties included) with its racing
    metrics (:mod:`arena.racing_metrics`); ``gap_to_winner_ms`` is 0 for the winner and
    null for a car that did not finish."""

    __tablename__ = "race_cars"
    __table_args__ = (
        UniqueConstraint("race_id", "car_name"),
        CheckConstraint(_in("status", ("finished", "dnf", "time_up")), name="status"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    race_id: Mapped[int] = mapped_column(ForeignKey("races.id", ondelete="CASCADE"), index=True)
    entry_id: Mapped[int | None] = mapped_column(
        ForeignKey("entries.id", ondelete="CASCADE"), nullable=True, index=True
    )
    model_id: Mapped[int | None] = mapped_column(
        ForeignKey("models.id", ondelete="CASCADE"), nullable=True
    )
    car_name: Mapped[str] = mapped_column(String(64))
    status: Mapped[str] = mapped_column(String(16))
    laps: Mapped[int] = mapped_column(Integer)
    lap_times_ms: Mapped[list[int]] = mapped_column(JSON)
    best_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    average_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    total_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    penalty_ms: Mapped[int] = mapped_column(Integer, default=0)
    off_track_count: Mapped[int] = mapped_column(Integer, default=0)
    crash_count: Mapped[int] = mapped_column(Integer, default=0)
    reset_count: Mapped[int] = mapped_column(Integer, default=0)
    distance_m: Mapped[float] = mapped_column(Float, default=0.0)
    finish_position: Mapped[int] = mapped_column(Integer)
    overtakes: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    times_overtaken: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    at_fault_collisions: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    laps_led: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    gap_to_winner_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    dnf_reason: Mapped[str | None] = mapped_column(Text, nullable=True)

    race: Mapped[Race] = relationship(back_populates="cars")


class Rating(Base):
    """A model's openskill (Plackett-Luce) rating within a head-to-head event."""

    __tablename__ = "ratings"
    __table_args__ = (UniqueConstraint("event_id", "model_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    event_id: Mapped[int] = mapped_column(ForeignKey("events.id", ondelete="CASCADE"), index=True)
    model_id: Mapped[int] = mapped_column(ForeignKey("models.id", ondelete="CASCADE"))
    mu: Mapped[float] = mapped_column(Float)
    sigma: Mapped[float] = mapped_column(Float)
    races: Mapped[int] = mapped_column(Integer, default=0)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)


TRAINING_STATUSES = ("queued", "running", "done", "failed", "stopped")
TRAINING_EVENT_KINDS = ("iteration", "poses", "log", "status")


class TrainingJob(Base):
    """A racer's training run on the league's trainers (:mod:`league.training`).

    ``spec`` holds what ``slipstream train`` takes, in its command-line forms (the reward
    function's source apart, in ``reward_source``); ``minutes`` is the budget the monthly
    quota reserves. A trainer leases the job as workers lease races, and while it runs
    writes :class:`TrainingEvent` rows (iterations, log lines). ``compute_seconds`` is
    the wall time it ran, which the monthly quota charges once it has ended; the run
    folder is stored as a zip (``run_sha256``) and its model becomes ``model_id``.
    """

    __tablename__ = "training_jobs"
    __table_args__ = (
        CheckConstraint(_in("status", TRAINING_STATUSES), name="status"),
        Index("ix_training_jobs_status_lease", "status", "lease_expires_at"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("racers.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(64))
    status: Mapped[str] = mapped_column(String(16), default="queued")
    priority: Mapped[int] = mapped_column(Integer, default=0)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    reward_source: Mapped[str] = mapped_column(Text)
    minutes: Mapped[float] = mapped_column(Float)
    clone_of_id: Mapped[int | None] = mapped_column(
        ForeignKey("training_jobs.id", ondelete="SET NULL"), nullable=True
    )
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    max_attempts: Mapped[int] = mapped_column(Integer, default=2)
    lease_owner: Mapped[str | None] = mapped_column(String(128), nullable=True)
    lease_expires_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    stop_requested_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    compute_seconds: Mapped[float] = mapped_column(Float, default=0.0)
    best_lap_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    run_sha256: Mapped[str | None] = mapped_column(String(64), nullable=True)
    model_id: Mapped[int | None] = mapped_column(
        ForeignKey("models.id", ondelete="SET NULL"), nullable=True
    )
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)

    owner: Mapped[Racer] = relationship(lazy="joined")


class TrainingEvent(Base):
    """One thing a training job reported: an iteration's metrics (with its evaluation, if
    any), the poses of one of its training races (the live top-down view), a log line,
    or a change of status. Ids grow, so they order a job's events and
    serve as the Server-Sent Events ids a viewer resumes from."""

    __tablename__ = "training_events"
    __table_args__ = (
        CheckConstraint(_in("kind", TRAINING_EVENT_KINDS), name="kind"),
        Index("ix_training_events_job_id_id", "job_id", "id"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("training_jobs.id", ondelete="CASCADE"))
    kind: Mapped[str] = mapped_column(String(16))
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
