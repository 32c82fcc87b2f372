"""Models judged by how they race: a model that breaks an event's races is suspended from it.

A car whose policy output NaN or inf, or whose steps were over the CPU budget, is out of
that race (a DNF with its reason, :class:`arena.race.StepGuard`); the race and its job
complete for the other cars. :func:`suspend_faulty` counts such DNFs per entry and event
and, at ``limit``, suspends the entry: it is left out of later rounds' grids, its queued
evaluation jobs are cancelled, and ``Entry.suspension`` says why, for its owner.
"""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from league.models import Entry, Job, Race, RaceCar, utcnow


def fault_count(session: Session, entry_id: int) -> int:
    """Races of the entry's event the entry was taken out of for a model fault."""
    query = (
        select(func.count(RaceCar.id))
        .join(Race, RaceCar.race_id == Race.id)
        .join(Entry, RaceCar.entry_id == Entry.id)
        .where(RaceCar.entry_id == entry_id, RaceCar.dnf_reason.is_not(None))
        .where(Race.event_id == Entry.event_id)
    )
    return session.scalar(query) or 0


def suspend_faulty(
    session: Session, entries: Iterable[Entry], limit: int, now: datetime | None = None
) -> list[Entry]:
    """Suspend each of ``entries`` with ``limit`` or more fault DNFs in its event (inside the
    caller's transaction, after the race's cars were added); the newly suspended ones."""
    now = now or utcnow()
    suspended = []
    for entry in entries:
        if entry.suspended_at is not None:
            continue
        faults = fault_count(session, entry.id)
        if faults < limit:
            continue
        last = session.scalar(
            select(RaceCar.dnf_reason)
            .where(RaceCar.entry_id == entry.id, RaceCar.dnf_reason.is_not(None))
            .order_by(RaceCar.id.desc())
            .limit(1)
        )
        entry.suspended_at = now
        entry.suspension = (
            f"Model {entry.model_id} was suspended from event {entry.event_id}: it was taken "
            f"out of {faults} of the event's races for model faults (the limit is {limit}); "
            f"the last: {last}. It races no more in this event; fix the model, upload it "
            "again and enter the new one."
        )
        session.execute(
            update(Job)
            .where(Job.entry_id == entry.id, Job.status == "queued")
            .values(status="failed", error=f"not raced: {entry.suspension}"[:4000])
        )
        suspended.append(entry)
    return suspended
