"""The scheduler daemon: turns entries into jobs, runs head-to-model rounds, closes events.

Each tick it (1) queues the missing evaluation jobs of time-trial, object-avoidance and
head-to-bot entries (one per event seed), (2) starts due head-to-model rounds (each race
on a fresh seed), (3) returns jobs with expired leases to the queue (or fails them), (4)
writes the final standings of closed events. Every write is safe with several schedulers
running: job inserts rely on the unique constraints (``ON CONFLICT DO NOTHING``), a round is
claimed by advancing the event's ``next_round_at`` with a conditional update, and a
snapshot is written only where none is.
"""

from __future__ import annotations

import logging
import random
import signal
from collections.abc import Collection
from datetime import datetime, timedelta

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from league.db import make_engine, make_session_factory
from league.jobs.matchmaking import Candidate, pairings, plan_round
from league.jobs.queue import (
    DB_ERRORS,
    Backoff,
    evaluation_jobs,
    expire_leases,
    insert_jobs,
    sleep_unless_stopped,
)
from league.models import Entry, Event, Job, Rating, utcnow
from league.ranking import initial_skill, leaderboard, standing_row
from league.settings import Settings

log = logging.getLogger("slipstream.scheduler")
ROUND_SEED_LIMIT = 2**31


def queue_evaluations(session: Session) -> int:
    """Jobs for entries of evaluation events that have none yet (one per event seed)."""
    pending = session.execute(
        select(Entry.id, Entry.event_id, Event.seeds)
        .join(Event, Entry.event_id == Event.id)
        .outerjoin(Job, Job.entry_id == Entry.id)
        .where(Event.race_type != "head_to_model", Job.id.is_(None))
    ).all()
    rows = [
        row
        for entry_id, event_id, seeds in pending
        for row in evaluation_jobs(event_id, entry_id, seeds)
    ]
    added = insert_jobs(session, rows)
    session.commit()
    return added


def _candidates(session: Session, event: Event) -> list[Candidate]:
    """The event's entries that may race (suspended ones may not), with their ratings."""
    start = initial_skill()
    rows = session.execute(
        select(Entry.id, Rating.mu, Rating.sigma)
        .outerjoin(Rating, (Rating.model_id == Entry.model_id) & (Rating.event_id == event.id))
        .where(Entry.event_id == event.id, Entry.suspended_at.is_(None))
        .order_by(Entry.id)
    ).all()
    return [
        Candidate(i, start.mu if mu is None else mu, start.sigma if sigma is None else sigma)
        for i, mu, sigma in rows
    ]


def round_seeds(event_id: int, number: int, count: int, used: Collection[int]) -> list[int]:
    """``count`` race seeds for round ``number`` of an event, none of them in ``used``.

    Drawn from a stream keyed by event and round, so a round's seeds are reproducible, and
    differ from round to round: the same lineup races a fresh seed every round.
    """
    stream = random.Random(f"seeds:{event_id}:{number}")
    taken, seeds = set(used), []
    while len(seeds) < count:
        seed = stream.randrange(ROUND_SEED_LIMIT)
        if seed not in taken:
            taken.add(seed)
            seeds.append(seed)
    return seeds


def _round_seeds_used(session: Session, event_id: int) -> list[int]:
    query = select(Job.seed).where(Job.event_id == event_id, Job.kind == "round")
    return list(session.scalars(query))


def _lineups(session: Session, event_id: int, number: int) -> list[list[dict]]:
    """The grids of round ``number`` of an event (none for round 0)."""
    query = select(Job.lineup).where(Job.event_id == event_id, Job.round == number)
    return [lineup or [] for lineup in session.scalars(query)]


def _round_busy(session: Session, event_id: int) -> bool:
    return (
        session.scalar(
            select(Job.id)
            .where(Job.event_id == event_id, Job.kind == "round")
            .where(Job.status.in_(("queued", "running")))
            .limit(1)
        )
        is not None
    )


def start_round(session: Session, event: Event, now: datetime, settings: Settings) -> int:
    """Claim the event's due round and queue its races; the number of jobs queued.

    Grids come from :func:`league.jobs.matchmaking.plan_round` (pairings of the previous round
    damped), seeds from :func:`round_seeds`.
    """
    due = event.next_round_at
    assert due is not None and event.round_interval_s
    following = due
    while following <= now:
        following += timedelta(seconds=event.round_interval_s)
    claimed = session.execute(
        update(Event)
        .where(Event.id == event.id, Event.next_round_at == due)
        .values(next_round_at=following)
    )
    if claimed.rowcount != 1:  # another scheduler took this round
        session.rollback()
        return 0
    if _round_busy(session, event.id):  # workers are behind: skip, do not pile rounds up
        session.commit()
        log.info("event %d: previous round still running; round skipped", event.id)
        return 0
    number = (session.scalar(select(func.max(Job.round)).where(Job.event_id == event.id)) or 0) + 1
    rng = random.Random(f"{event.id}:{number}")
    grids = plan_round(
        _candidates(session, event),
        settings.round_races_per_model,
        settings.round_max_cars,
        rng,
        recent=pairings(_lineups(session, event.id, number - 1)),
        bot=event.round_bot,
    )
    seeds = round_seeds(event.id, number, len(grids), _round_seeds_used(session, event.id))
    rows = [
        {"kind": "round", "event_id": event.id, "round": number, "seed": seed, "lineup": grid}
        for seed, grid in zip(seeds, grids, strict=True)
    ]
    added = insert_jobs(session, rows)
    session.commit()
    log.info("event %d: round %d with %d races", event.id, number, added)
    return added


def due_rounds(session: Session, now: datetime, settings: Settings) -> int:
    """Start every head-to-model round that is due; jobs queued."""
    events = session.scalars(
        select(Event).where(
            Event.race_type == "head_to_model",
            Event.next_round_at.is_not(None),
            Event.next_round_at <= now,
        )
    ).all()
    session.commit()
    return sum(start_round(session, e, now, settings) for e in events if e.is_open(now))


def close_events(session: Session, now: datetime) -> int:
    """Snapshot the standings of closed league events whose jobs have all settled; how
    many. Evaluations have no standings to keep: their races are their record."""
    events = session.scalars(
        select(Event).where(
            Event.kind == "league",
            Event.closes_at.is_not(None),
            Event.closes_at <= now,
            Event.finalized_at.is_(None),
        )
    ).all()
    closed = 0
    for event in events:
        busy = session.scalar(
            select(Job.id)
            .where(Job.event_id == event.id, Job.status.in_(("queued", "running")))
            .limit(1)
        )
        if busy is not None:
            continue
        rows = [standing_row(s) for s in leaderboard(session, event)]
        done = session.execute(
            update(Event)
            .where(Event.id == event.id, Event.finalized_at.is_(None))
            .values(final_standings=rows, finalized_at=now)
        )
        session.commit()
        if done.rowcount == 1:
            closed += 1
            log.info("event %d closed; final standings of %d racers written", event.id, len(rows))
    return closed


class Scheduler:
    """The daemon: one :meth:`tick` every ``poll_seconds`` until SIGTERM / SIGINT."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.engine = make_engine(settings.db_url, settings.sqlite_busy_timeout_ms)
        self.sessions = make_session_factory(self.engine)
        self.stopping = False

    def stop(self, *_args: object) -> None:
        """Leave the loop after the current tick (signal handler)."""
        self.stopping = True

    def tick(self, now: datetime | None = None) -> dict[str, int]:
        """One pass over the four duties; counts of what it did."""
        now = now or utcnow()
        with self.sessions() as session:
            jobs = queue_evaluations(session)
            rounds = due_rounds(session, now, self.settings)
            requeued, failed = expire_leases(session, now)
            closed = close_events(session, now)
        done = {"evaluation_jobs": jobs, "round_jobs": rounds, "requeued": requeued}
        done |= {"failed": failed, "closed": closed}
        if any(done.values()):
            log.info("tick: %s", ", ".join(f"{k} {v}" for k, v in done.items() if v))
        return done

    def run_forever(self) -> None:
        """Tick until stopped; back off while the database is unreachable."""
        for stop_signal in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
            signal.signal(stop_signal, self.stop)
        backoff = Backoff()
        log.info("scheduler started")
        while not self.stopping:
            try:
                self.tick()
                backoff.reset()
                wait = self.settings.poll_seconds
            except DB_ERRORS as exc:
                wait = backoff.next()
                log.warning(
                    "database unavailable (%s); retrying in %.1f s", type(exc).__name__, wait
                )
            sleep_unless_stopped(wait, lambda: self.stopping)
        self.engine.dispose()
        log.info("scheduler stopped")


def main() -> None:
    """``python -m league.jobs.scheduler``: the daemon with settings from the environment."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    Scheduler(Settings()).run_forever()


if __name__ == "__main__":
    main()
