"""Live training events for many viewers: one database poll per job and server process.

Every viewer of a job's Server-Sent Events stream reads the same rows, so each server
process polls a job's new events once (every :data:`POLL_SECONDS` while anyone watches)
and hands them to all its viewers; a hundred viewers cost the database what one does, and
the trainer is never asked anything. A viewer who resumes from an older event id first
reads the rows it missed itself, then follows the shared feed.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field

from fastapi.concurrency import run_in_threadpool
from sqlalchemy import select
from sqlalchemy.orm import Session

from league.models import TrainingEvent, TrainingJob
from league.training.queue import ENDED

POLL_SECONDS = 0.5
KEEPALIVE_SECONDS = 15.0
BATCH = 500


@dataclass(frozen=True)
class FeedEvent:
    """One event as viewers receive it."""

    id: int
    kind: str
    data: dict


def read_events(session: Session, job_id: int, after: int, limit: int = BATCH) -> list[FeedEvent]:
    """A job's events after the id ``after``, oldest first."""
    rows = session.scalars(
        select(TrainingEvent)
        .where(TrainingEvent.job_id == job_id, TrainingEvent.id > after)
        .order_by(TrainingEvent.id)
        .limit(limit)
    )
    return [FeedEvent(row.id, row.kind, row.data) for row in rows]


@dataclass
class _JobFeed:
    """One job's shared poll: the last batch read (the events after ``batch_after``)."""

    last_id: int
    batch_after: int = 0
    batch: list[FeedEvent] = field(default_factory=list)
    viewers: int = 0
    ended: bool = False
    changed: asyncio.Condition = field(default_factory=asyncio.Condition)


class TrainingFeed:
    """The shared polls of one server process (``app.state.training_feed``)."""

    def __init__(self, sessions: Callable[[], Session]) -> None:
        self._sessions = sessions
        self._feeds: dict[int, _JobFeed] = {}

    def _read(self, job_id: int, after: int) -> tuple[list[FeedEvent], bool]:
        """Events after ``after``, and whether the job has ended with nothing more to read."""
        with self._sessions() as session:
            # the status first: a job seen ended has committed its last events before
            status = session.scalar(select(TrainingJob.status).where(TrainingJob.id == job_id))
            events = read_events(session, job_id, after)
        return events, status is None or (status in ENDED and len(events) < BATCH)

    async def _poll(self, job_id: int, feed: _JobFeed) -> None:
        """Read the job's new events while anyone watches and it has not ended."""
        try:
            while feed.viewers > 0 and not feed.ended:
                events, ended = await run_in_threadpool(self._read, job_id, feed.last_id)
                async with feed.changed:
                    if events:
                        feed.batch_after, feed.batch = feed.last_id, events
                        feed.last_id = events[-1].id
                    feed.ended = ended
                    if events or ended:
                        feed.changed.notify_all()
                if not events:
                    await asyncio.sleep(POLL_SECONDS)
        finally:
            if self._feeds.get(job_id) is feed:
                del self._feeds[job_id]
            async with feed.changed:
                feed.ended = True
                feed.changed.notify_all()

    def _join(self, job_id: int, after: int) -> _JobFeed:
        feed = self._feeds.get(job_id)
        if feed is None or feed.ended:
            feed = _JobFeed(last_id=after)
            self._feeds[job_id] = feed
            feed.viewers += 1
            asyncio.get_running_loop().create_task(self._poll(job_id, feed))
        else:
            feed.viewers += 1
        return feed

    async def follow(self, job_id: int, after: int) -> AsyncIterator[FeedEvent | None]:
        """The job's events after the id ``after`` as they come, ending once the job has
        ended; None after :data:`KEEPALIVE_SECONDS` of quiet (a keep-alive comment)."""
        feed = self._join(job_id, after)
        try:
            while True:
                quiet = False
                async with feed.changed:
                    if feed.last_id <= after and not feed.ended:
                        try:
                            await asyncio.wait_for(feed.changed.wait(), KEEPALIVE_SECONDS)
                        except TimeoutError:
                            quiet = True
                    batch_after, batch, last_id = feed.batch_after, feed.batch, feed.last_id
                    ended = feed.ended
                if after < batch_after or (after < last_id and not batch):
                    # behind the shared batch (resumed from an old id, or slow): catch up
                    events, _ended = await run_in_threadpool(self._read, job_id, after)
                elif after < last_id:
                    events = [e for e in batch if e.id > after]
                else:
                    events = []
                for event in events:
                    after = event.id
                    yield event
                if not events and ended:
                    return
                if quiet:
                    yield None
        finally:
            feed.viewers -= 1
