"""The file store's start-up sweep: crash leftovers and files that no row refers to.

A process killed mid-upload or mid-race can leave a ``.tmp-*`` file, or a stored file whose
row never committed. At start the server removes both, but only those last modified more
than a grace period ago: in a deployment of several processes a younger file may be a write
in progress elsewhere. A candidate orphan is renamed aside first, then looked up again;
it goes back if a row now refers to it or it was touched meanwhile
(:meth:`league.storage.Storage.put` refreshes the mtime of a file it finds), so a file whose
row is being written right now is never deleted. A database that refers to no file of a
kind at all (a fresh one, or the wrong one) sweeps none of that kind.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from itertools import islice
from pathlib import Path
from typing import TypeVar

from sqlalchemy import select
from sqlalchemy.orm import Session

from league.models import Model, Race
from league.storage import TEMP_PREFIX, Storage

log = logging.getLogger("slipstream.sweep")
REFERENCES = {"models": Model.sha256, "traces": Race.trace_sha256}
"""Which column refers to the stored files of each kind."""
BATCH = 500
T = TypeVar("T")


@dataclass(frozen=True)
class SweepReport:
    """How many files one sweep removed."""

    temp: int
    unreferenced: dict[str, int]


def sweep(
    sessions: Callable[[], Session], storage: Storage, grace_s: float, now: float | None = None
) -> SweepReport:
    """Remove temp files and files of every kind no row refers to, older than ``grace_s``."""
    cutoff = (time.time() if now is None else now) - grace_s
    temp = sum(_unlink(path) for path in list(storage.temp_files(cutoff)))
    unreferenced = {kind: _sweep_kind(sessions, storage, kind, cutoff) for kind in REFERENCES}
    report = SweepReport(temp, unreferenced)
    log.info("start-up sweep removed %d temp file(s) and unreferenced files %s", temp, unreferenced)
    return report


def _sweep_kind(
    sessions: Callable[[], Session], storage: Storage, kind: str, cutoff: float
) -> int:
    removed = 0
    for index, batch in enumerate(_batched(storage.stored(kind, cutoff), BATCH)):
        if index == 0 and not _refers_to_any(sessions, kind):
            log.warning(
                "the database refers to no %s files: not sweeping them (is it the right one?)",
                kind,
            )
            return 0
        removed += _remove_unreferenced(sessions, kind, batch, cutoff)
    return removed


def _refers_to_any(sessions: Callable[[], Session], kind: str) -> bool:
    """Whether any row refers to a file of ``kind`` (an empty database, perhaps the wrong
    one, must not empty the store)."""
    column = REFERENCES[kind]
    with sessions() as session:
        return session.scalar(select(column).where(column.is_not(None)).limit(1)) is not None


def _remove_unreferenced(
    sessions: Callable[[], Session], kind: str, batch: list[tuple[str, Path]], cutoff: float
) -> int:
    column = REFERENCES[kind]
    with sessions() as session:
        known = set(session.scalars(select(column).where(column.in_([s for s, _ in batch]))))
    removed = 0
    for sha256, path in batch:
        if sha256 in known:
            continue
        aside = path.with_name(f"{TEMP_PREFIX}orphan-{path.name}")
        try:
            os.rename(path, aside)
        except FileNotFoundError:  # another server's sweep got there first
            continue
        with sessions() as session:
            wanted = session.scalar(select(column).where(column == sha256).limit(1)) is not None
        if wanted or aside.stat().st_mtime >= cutoff:
            _put_back(aside, path)
        else:
            removed += _unlink(aside)
    return removed


def _put_back(aside: Path, path: Path) -> None:
    """Return a renamed-aside file (an upload may have written the same bytes anew)."""
    if path.exists():
        aside.unlink()
    else:
        os.replace(aside, path)


def _unlink(path: Path) -> int:
    try:
        path.unlink()
    except FileNotFoundError:
        return 0
    except OSError as exc:
        log.warning("could not remove %s: %s", path, exc)
        return 0
    return 1


def _batched(items: Iterable[T], size: int) -> Iterator[list[T]]:
    iterator = iter(items)
    while batch := list(islice(iterator, size)):
        yield batch
