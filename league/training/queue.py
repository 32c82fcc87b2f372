"""Training jobs in the database: quotas, leasing, heartbeats, events, and how a job ends.

Trainers lease training jobs as workers lease races (:mod:`league.jobs.queue`): a lease is a
conditional update from ``queued`` to ``running`` with a fresh owner token, so two trainers
never run one job, and a trainer whose lease expired can no longer heartbeat, report or
finish it. A lease also honours the admin's quotas: at most ``training_jobs_total`` jobs
run at once and at most ``training_jobs_per_racer`` of one racer's; the others wait, the
highest ``priority`` first, then the oldest. So that two trainers cannot both take the last
free place, a lease runs under the database's write lock (SQLite) or a transaction-scoped
advisory lock (PostgreSQL).

The monthly quota is charged in minutes: a job that has ended costs the wall time it ran,
one that is queued or running its whole budget (what it may still use).
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import ColumnElement, and_, func, select, text, update
from sqlalchemy.orm import Session

from league.models import TrainingEvent, TrainingJob, utcnow
from league.settings import Settings

ACTIVE = ("queued", "running")
ENDED = ("done", "failed", "stopped")
_LEASE_LOCK = 7_300_233
"""PostgreSQL advisory lock key that serialises training leases."""


class QuotaExceeded(RuntimeError):
    """A new job would pass one of the admin's quotas; the message says which and when it
    resets (``retry_after`` seconds, when waiting helps)."""

    def __init__(self, message: str, retry_after: int | None = None) -> None:
        super().__init__(message)
        self.retry_after = retry_after


@dataclass(frozen=True)
class TrainingLease:
    """A training job held by one trainer until ``expires_at`` (heartbeats extend it)."""

    job_id: int
    owner: str
    attempt: int
    expires_at: datetime


def month_start(now: datetime) -> datetime:
    """Midnight UTC on the first day of ``now``'s month."""
    now = now.astimezone(UTC)
    return datetime(now.year, now.month, 1, tzinfo=UTC)


def next_month(now: datetime) -> datetime:
    """Midnight UTC on the first day of the month after ``now``'s: when quotas reset."""
    start = month_start(now)
    return datetime(start.year + start.month // 12, start.month % 12 + 1, 1, tzinfo=UTC)


def minutes_used(session: Session, racer_id: int, now: datetime | None = None) -> float:
    """Training minutes ``racer_id`` has used or reserved this month (module docstring)."""
    since = month_start(now or utcnow())
    ended = session.scalar(
        select(func.coalesce(func.sum(TrainingJob.compute_seconds), 0.0)).where(
            TrainingJob.owner_id == racer_id,
            TrainingJob.status.in_(ENDED),
            TrainingJob.finished_at >= since,
        )
    )
    reserved = session.scalar(
        select(func.coalesce(func.sum(TrainingJob.minutes), 0.0)).where(
            TrainingJob.owner_id == racer_id, TrainingJob.status.in_(ACTIVE)
        )
    )
    return float(ended) / 60.0 + float(reserved)


def check_quotas(session: Session, settings: Settings, racer_id: int, minutes: float) -> None:
    """Raise :class:`QuotaExceeded` when a new job of ``minutes`` would pass a quota."""
    if minutes > settings.training_max_minutes:
        raise QuotaExceeded(
            f"A training job may last at most {settings.training_max_minutes:g} minutes "
            f"(the league's training_max_minutes); {minutes:g} were asked for."
        )
    active = session.scalar(
        select(func.count())
        .select_from(TrainingJob)
        .where(TrainingJob.owner_id == racer_id, TrainingJob.status.in_(ACTIVE))
    )
    if active >= settings.training_queued_per_racer:
        raise QuotaExceeded(
            f"You have {active} training jobs queued or running, the most one racer may "
            "have (training_queued_per_racer); start the next when one has ended.",
            retry_after=60,
        )
    now = utcnow()
    used = minutes_used(session, racer_id, now)
    left = settings.training_minutes_per_month - used
    if minutes > left + 1e-9:
        reset = next_month(now)
        raise QuotaExceeded(
            f"This job's {minutes:g} minutes would pass your monthly training quota of "
            f"{settings.training_minutes_per_month:g} minutes ({used:.1f} used or reserved, "
            f"{max(left, 0.0):.1f} left); it resets on {reset:%Y-%m-%d} at 00:00 UTC.",
            retry_after=int((reset - now).total_seconds()) + 1,
        )


def add_event(session: Session, job_id: int, kind: str, data: dict[str, Any]) -> None:
    """Append one event to a job (the caller commits)."""
    session.add(TrainingEvent(job_id=job_id, kind=kind, data=data))


def _lock_leases(session: Session) -> None:
    """Serialise leases: SQLite's write lock, or PostgreSQL's advisory lock."""
    if session.get_bind().dialect.name == "postgresql":
        session.execute(select(func.pg_advisory_xact_lock(_LEASE_LOCK)))
    else:
        session.execute(text("UPDATE training_jobs SET id = id WHERE 0"))


def lease_training(
    session: Session, settings: Settings, trainer: str, lease_s: float
) -> TrainingLease | None:
    """Lease the next training job the quotas allow (module docstring); commit and return
    the lease, or None when nothing may start."""
    _lock_leases(session)
    running = select(TrainingJob.owner_id).where(TrainingJob.status == "running")
    owners = list(session.scalars(running))
    if len(owners) >= settings.training_jobs_total:
        session.rollback()
        return None
    full = {o for o in owners if owners.count(o) >= settings.training_jobs_per_racer}
    query = (
        select(TrainingJob.id)
        .where(TrainingJob.status == "queued", TrainingJob.owner_id.not_in(full))
        .order_by(TrainingJob.priority.desc(), TrainingJob.id)
        .limit(1)
    )
    job_id = session.scalar(query)
    if job_id is None:
        session.rollback()
        return None
    now = utcnow()
    owner = f"{trainer}#{uuid.uuid4().hex[:12]}"
    expires = now + timedelta(seconds=lease_s)
    attempt = session.execute(
        update(TrainingJob)
        .where(TrainingJob.id == job_id, TrainingJob.status == "queued")
        .values(
            status="running",
            lease_owner=owner,
            lease_expires_at=expires,
            attempts=TrainingJob.attempts + 1,
            started_at=now,
            error=None,
        )
        .returning(TrainingJob.attempts)
    ).scalar_one()
    add_event(session, job_id, "status", {"status": "running", "trainer": trainer})
    session.commit()
    return TrainingLease(job_id, owner, attempt, expires)


def _owned(lease: TrainingLease) -> ColumnElement[bool]:
    return and_(
        TrainingJob.id == lease.job_id,
        TrainingJob.lease_owner == lease.owner,
        TrainingJob.status == "running",
    )


def heartbeat_training(
    session: Session, lease: TrainingLease, lease_s: float
) -> tuple[TrainingLease | None, bool]:
    """Extend a held lease: ``(lease, stop_requested)``; the lease is None when the job is
    no longer this trainer's."""
    expires = utcnow() + timedelta(seconds=lease_s)
    moved = session.execute(
        update(TrainingJob)
        .where(_owned(lease))
        .values(lease_expires_at=expires)
        .returning(TrainingJob.stop_requested_at)
    ).all()
    session.commit()
    if len(moved) != 1:
        return None, False
    renewed = TrainingLease(lease.job_id, lease.owner, lease.attempt, expires)
    return renewed, moved[0][0] is not None


def report(session: Session, lease: TrainingLease, events: list[tuple[str, dict]]) -> bool:
    """Store a running job's events, if the lease still holds it; commit. Iteration events
    with an evaluation lap also update the job's best lap."""
    if session.scalar(select(TrainingJob.id).where(_owned(lease))) is None:
        session.rollback()
        return False
    best = None
    for kind, data in events:
        add_event(session, lease.job_id, kind, data)
        lap = (data.get("eval") or {}).get("best_lap") if kind == "iteration" else None
        if lap is not None:
            best = lap if best is None else min(best, lap)
    if best is not None:
        job = session.get_one(TrainingJob, lease.job_id)
        ms = round(best * 1000)
        job.best_lap_ms = ms if job.best_lap_ms is None else min(job.best_lap_ms, ms)
    session.commit()
    return True


def finish_training(
    session: Session,
    lease: TrainingLease,
    status: str,
    compute_seconds: float,
    error: str | None = None,
    run_sha256: str | None = None,
    model_id: int | None = None,
) -> bool:
    """End a leased job as ``done``, ``stopped`` or ``failed`` if the lease still holds it;
    commit. False when it was no longer this trainer's."""
    values: dict[str, Any] = {
        "status": status,
        "lease_owner": None,
        "lease_expires_at": None,
        "finished_at": utcnow(),
        "compute_seconds": TrainingJob.compute_seconds + compute_seconds,
        "error": error[:4000] if error else None,
    }
    if run_sha256 is not None:
        values["run_sha256"] = run_sha256
    if model_id is not None:
        values["model_id"] = model_id
    moved = session.execute(update(TrainingJob).where(_owned(lease)).values(values))
    if moved.rowcount != 1:
        session.rollback()
        return False
    add_event(session, lease.job_id, "status", {"status": status, "error": error})
    session.commit()
    return True


def give_back(session: Session, lease: TrainingLease, compute_seconds: float, why: str) -> None:
    """Requeue a leased job untouched (trainer shutdown), this attempt not counted; commit."""
    moved = session.execute(
        update(TrainingJob)
        .where(_owned(lease))
        .values(
            status="queued",
            lease_owner=None,
            lease_expires_at=None,
            attempts=TrainingJob.attempts - 1,
            compute_seconds=TrainingJob.compute_seconds + compute_seconds,
        )
    )
    if moved.rowcount == 1:
        add_event(session, lease.job_id, "status", {"status": "queued", "error": why})
    session.commit()


def expire_training_leases(session: Session) -> tuple[int, int]:
    """Requeue running jobs whose trainer stopped heartbeating, or fail them (with the
    reason) when their attempts are spent; ``(requeued, failed)``. Commits."""
    now = utcnow()
    expired = and_(TrainingJob.status == "running", TrainingJob.lease_expires_at < now)
    stale = session.execute(
        select(TrainingJob.id, TrainingJob.lease_owner, TrainingJob.attempts,
               TrainingJob.max_attempts, TrainingJob.started_at).where(expired)
    ).all()  # fmt: skip
    requeued = failed = 0
    for job_id, owner, attempts, max_attempts, started in stale:
        out = attempts >= max_attempts
        note = f"the trainer {owner.partition('#')[0]} stopped (its lease expired)"
        error = f"{note}; gave up after {attempts} attempts" if out else None
        ran = (now - started).total_seconds() if started else 0.0
        moved = session.execute(
            update(TrainingJob)
            .where(TrainingJob.id == job_id, TrainingJob.lease_owner == owner, expired)
            .values(
                status="failed" if out else "queued",
                lease_owner=None,
                lease_expires_at=None,
                error=error,
                compute_seconds=TrainingJob.compute_seconds + ran,
                finished_at=now if out else None,
            )
        )
        if moved.rowcount == 1:
            status = "failed" if out else "queued"
            add_event(session, job_id, "status", {"status": status, "error": error or note})
            failed += out
            requeued += not out
    session.commit()
    return requeued, failed


def request_stop(session: Session, job: TrainingJob) -> None:
    """Stop a job: a queued one ends now, a running one when its trainer next heartbeats
    (it keeps what was trained). Commits."""
    now = utcnow()
    if job.status == "queued":
        job.status = "stopped"
        job.finished_at = now
        add_event(session, job.id, "status", {"status": "stopped", "error": None})
    elif job.status == "running" and job.stop_requested_at is None:
        job.stop_requested_at = now
        add_event(session, job.id, "log", {"line": "stop requested"})
    session.commit()
