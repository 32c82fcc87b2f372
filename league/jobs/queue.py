"""The job queue in the database: queuing, leasing, heartbeats, completion and lease expiry.

The queue is fair: jobs wait in lanes, one per racer (their evaluation jobs) and one per
head-to-model event (its round jobs), and :func:`lease_job` serves the lanes in turn: the
lane served longest ago (or never) gives its oldest job. One racer's hundred jobs wait
behind everyone else's next one, and a flood of evaluations cannot starve an event's
rounds. When a lane was last served is kept on its racer (``queue_served_at``) or event
(``rounds_served_at``), written in the lease's transaction.

A lease is a conditional update: a job moves from ``queued`` to ``running`` only if it is
still queued, so two workers can never both win it (on PostgreSQL a second worker's update
waits for the first's commit and then finds the job running; SQLite serialises writers).
Every lease gets a fresh owner token, so a worker whose lease expired (and whose job
another worker took) can never heartbeat, finish or fail it. A job becomes ``done`` only
through :func:`claim_done`.
"""

from __future__ import annotations

import random
import time
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import ColumnElement, and_, case, func, select, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.exc import InterfaceError, OperationalError
from sqlalchemy.orm import Session

from league.models import Entry, Event, Job, Racer, utcnow

DB_ERRORS = (OperationalError, InterfaceError)
"""What an unreachable or locked database raises: wait and try again."""


@dataclass(frozen=True)
class Lease:
    """A job held by one worker until ``expires_at`` (unless heartbeats extend it)."""

    job_id: int
    owner: str
    attempt: int
    expires_at: datetime


class Backoff:
    """Exponential backoff with jitter: 0.5 s doubling up to ``cap`` seconds."""

    def __init__(self, cap: float = 10.0) -> None:
        self.cap = cap
        self.delay = 0.0

    def next(self) -> float:
        """The next wait, in seconds."""
        self.delay = min(self.cap, max(0.5, self.delay * 2))
        return self.delay * random.uniform(0.75, 1.25)

    def reset(self) -> None:
        """Back to the shortest wait after a success."""
        self.delay = 0.0


def sleep_unless_stopped(seconds: float, stopping: Callable[[], bool], tick: float = 0.2) -> None:
    """Sleep ``seconds``, waking every ``tick`` to leave early once ``stopping()`` is true."""
    end = time.monotonic() + seconds
    while not stopping():
        left = end - time.monotonic()
        if left <= 0.0:  # checked after reading the clock: a late wake-up never sleeps < 0
            return
        time.sleep(min(tick, left))


def evaluation_jobs(event_id: int, entry_id: int, seeds: Iterable[int]) -> list[dict[str, Any]]:
    """The job rows that evaluate one entry: one per seed of its event."""
    return [
        {"kind": "evaluation", "event_id": event_id, "entry_id": entry_id, "seed": seed}
        for seed in seeds
    ]


def insert_jobs(session: Session, rows: list[dict[str, Any]]) -> int:
    """Insert job rows, skipping any that already exist (unique keys); how many were new."""
    if not rows:
        return 0
    dialect = postgresql if session.get_bind().dialect.name == "postgresql" else sqlite
    statement = dialect.insert(Job).values(rows).on_conflict_do_nothing().returning(Job.id)
    return len(session.execute(statement).all())


def _owned(lease: Lease) -> ColumnElement[bool]:
    return and_(Job.id == lease.job_id, Job.lease_owner == lease.owner, Job.status == "running")


def _lane_heads(limit: int):
    """The oldest queued job of each lane, lanes served longest ago (or never) first."""
    rounds = Job.kind == "round"
    lane = case((rounds, -Job.event_id), else_=func.coalesce(Entry.racer_id, 0))
    served = case((rounds, Event.rounds_served_at), else_=Racer.queue_served_at)
    heads = (
        select(lane.label("lane"), func.min(Job.id).label("job_id"), func.max(served).label("at"))
        .select_from(Job)
        .join(Event, Event.id == Job.event_id)
        .outerjoin(Entry, Entry.id == Job.entry_id)
        .outerjoin(Racer, Racer.id == Entry.racer_id)
        .where(Job.status == "queued")
        .group_by(lane)
        .subquery()
    )
    return (
        select(heads.c.job_id, heads.c.lane)
        .order_by(heads.c.at.asc().nulls_first(), heads.c.job_id)
        .limit(limit)
    )


def _mark_served(session: Session, lane: int, now: datetime) -> None:
    if lane < 0:
        session.execute(update(Event).where(Event.id == -lane).values(rounds_served_at=now))
    elif lane > 0:
        session.execute(update(Racer).where(Racer.id == lane).values(queue_served_at=now))


def lease_job(
    session: Session, worker: str, lease_s: float, now: datetime | None = None
) -> Lease | None:
    """Lease the next job for ``worker``, lanes in turn (see the module docstring); commit
    and return the lease, or None when nothing is queued."""
    now = now or utcnow()
    for job_id, lane in session.execute(_lane_heads(8)).all():
        owner = f"{worker}#{uuid.uuid4().hex[:12]}"
        expires = now + timedelta(seconds=lease_s)
        won = session.execute(
            update(Job)
            .where(Job.id == job_id, Job.status == "queued")
            .values(
                status="running",
                lease_owner=owner,
                lease_expires_at=expires,
                attempts=Job.attempts + 1,
                updated_at=now,
            )
            .returning(Job.attempts)
        ).scalar_one_or_none()
        if won is not None:
            _mark_served(session, lane, now)
            session.commit()
            return Lease(job_id, owner, won, expires)
    session.rollback()
    return None


def heartbeat(session: Session, lease: Lease, lease_s: float) -> Lease | None:
    """Extend a held lease; None when the job is no longer ours (it expired and moved on)."""
    expires = utcnow() + timedelta(seconds=lease_s)
    done = session.execute(
        update(Job).where(_owned(lease)).values(lease_expires_at=expires, updated_at=utcnow())
    )
    session.commit()
    if done.rowcount != 1:
        return None
    return Lease(lease.job_id, lease.owner, lease.attempt, expires)


def claim_done(session: Session, lease: Lease) -> bool:
    """Inside the caller's transaction, mark the leased job done if it is still ours.

    The first statement of the result transaction: on SQLite it takes the write lock, on
    PostgreSQL it locks the job row, so the result rows that follow are written at most once.
    """
    done = session.execute(
        update(Job)
        .where(_owned(lease))
        .values(status="done", lease_owner=None, lease_expires_at=None, error=None)
    )
    return done.rowcount == 1


def fail_job(session: Session, lease: Lease, error: str, retry: bool) -> bool:
    """Record ``error``; requeue when ``retry`` and attempts remain, else fail. Commits."""
    job = session.execute(select(Job).where(_owned(lease))).scalar_one_or_none()
    if job is None:
        session.rollback()
        return False
    again = retry and job.attempts < job.max_attempts
    job.status = "queued" if again else "failed"
    job.error = error[:4000]
    job.lease_owner = None
    job.lease_expires_at = None
    session.commit()
    return True


def release(session: Session, lease: Lease) -> None:
    """Give a job back untouched (worker shutdown): queued again, this attempt not counted."""
    session.execute(
        update(Job)
        .where(_owned(lease))
        .values(
            status="queued",
            lease_owner=None,
            lease_expires_at=None,
            attempts=Job.attempts - 1,
        )
    )
    session.commit()


def expire_leases(session: Session, now: datetime | None = None) -> tuple[int, int]:
    """Requeue running jobs whose lease ran out, or fail them when out of attempts.

    The last error is kept: a failed job's ``error`` says how many attempts were made and
    what went wrong last. Returns ``(requeued, failed)``. Commits.
    """
    now = now or utcnow()
    expired = and_(Job.status == "running", Job.lease_expires_at < now)
    stale = session.execute(
        select(Job.id, Job.lease_owner, Job.attempts, Job.max_attempts, Job.error).where(expired)
    ).all()
    requeued = failed = 0
    for job_id, owner, attempts, max_attempts, error in stale:
        note = f"lease of {owner} expired (worker stopped heartbeating)"
        out = attempts >= max_attempts
        values = {
            "status": "failed" if out else "queued",
            "lease_owner": None,
            "lease_expires_at": None,
            "error": (
                f"gave up after {attempts} attempts; last error: {error or note}" if out else note
            ),
        }
        moved = session.execute(
            update(Job).where(Job.id == job_id, Job.lease_owner == owner, expired).values(values)
        )
        if moved.rowcount == 1:
            failed += out
            requeued += not out
    session.commit()
    return requeued, failed
