"""The file store's start-up sweep: crash leftovers and files that no row refers to.

A process killed mid-upload or mid-race can leave a ``.tmp-*`` file, or a stored file whose
row never committed. At start the server removes both, but only those last modified more
than a grace period ago: in a deployment of several processes a younger file may be a write
in progress elsewhere. A candidate orphan is taken out of reach first, then looked up again
(:meth:`league.store.base.FileStore.remove_orphan`); it goes back if a row now refers to it or
it was stored again meanwhile (``put`` marks a file it finds fresh), so a file whose row is
being written right now is kept. A database that refers to no file of a kind at all (a
fresh one, or the wrong one) sweeps none of that kind. The store may be a local directory
or an object-storage bucket: this module only speaks :class:`league.store.base.FileStore`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from functools import partial
from itertools import islice
from typing import TypeVar

from sqlalchemy import select
from sqlalchemy.orm import Session

from league.models import Model, Race, TrainingJob
from league.store.base import FileStore

log = logging.getLogger("slipstream.sweep")
REFERENCES = {
    "models": Model.sha256,
    "traces": Race.trace_sha256,
    "runs": TrainingJob.run_sha256,
}
"""Which column refers to the stored files of each kind."""
BATCH = 500
T = TypeVar("T")


@dataclass(frozen=True)
class SweepReport:
    """How many files one sweep removed."""

    temp: int
    unreferenced: dict[str, int]


def sweep(
    sessions: Callable[[], Session], storage: FileStore, grace_s: float, now: float | None = None
) -> SweepReport:
    """Remove temp files and files of every kind no row refers to, older than ``grace_s``."""
    cutoff = (time.time() if now is None else now) - grace_s
    temp = storage.remove_temp(cutoff)
    unreferenced = {kind: _sweep_kind(sessions, storage, kind, cutoff) for kind in REFERENCES}
    report = SweepReport(temp, unreferenced)
    log.info("start-up sweep removed %d temp file(s) and unreferenced files %s", temp, unreferenced)
    return report


def _sweep_kind(
    sessions: Callable[[], Session], storage: FileStore, kind: str, cutoff: float
) -> int:
    removed = 0
    for index, batch in enumerate(_batched(storage.stored(kind, cutoff), BATCH)):
        if index == 0 and not _refers_to_any(sessions, kind):
            log.warning(
                "the database refers to no %s files: not sweeping them (is it the right one?)",
                kind,
            )
            return 0
        removed += _remove_unreferenced(sessions, storage, kind, batch, cutoff)
    return removed


def _refers_to_any(sessions: Callable[[], Session], kind: str) -> bool:
    """Whether any row refers to a file of ``kind`` (an empty database, perhaps the wrong
    one, must not empty the store)."""
    column = REFERENCES[kind]
    with sessions() as session:
        return session.scalar(select(column).where(column.is_not(None)).limit(1)) is not None


def _remove_unreferenced(
    sessions: Callable[[], Session],
    storage: FileStore,
    kind: str,
    batch: list[str],
    cutoff: float,
) -> int:
    column = REFERENCES[kind]
    with sessions() as session:
        known = set(session.scalars(select(column).where(column.in_(batch))))

    def wanted(sha256: str) -> bool:
        with sessions() as session:
            return session.scalar(select(column).where(column == sha256).limit(1)) is not None

    removed = 0
    for sha256 in batch:
        if sha256 not in known:
            removed += storage.remove_orphan(kind, sha256, cutoff, partial(wanted, sha256))
    return removed


def _batched(items: Iterable[T], size: int) -> Iterator[list[T]]:
    iterator = iter(items)
    while batch := list(islice(iterator, size)):
        yield batch
