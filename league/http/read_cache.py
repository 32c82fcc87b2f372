"""Prepared answers for the public reads: bodies built once per results version.

Every cached body is keyed by its route's inputs and the version of the data it shows (an
event's ``results_version``, which :func:`league.crud.bump_results_version` bumps in the
transaction that changes a result). A request reads that version first (one indexed query,
so several server processes stay correct without telling each other anything) and, when a
body was built at that version, answers it, or ``304 Not Modified`` when the client's
``If-None-Match`` already names it. Entries whose version moved on simply age out (LRU).
"""

from __future__ import annotations

import asyncio
import gzip
import hashlib
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

from fastapi.concurrency import run_in_threadpool
from sqlalchemy import Dialect, Engine, Select, bindparam, func, select
from starlette.requests import Request
from starlette.responses import Response

from league.models import Event, Race

NO_CACHE = "no-cache"
IMMUTABLE = "public, max-age=31536000, immutable"


@dataclass(frozen=True)
class Prepared:
    """A ready answer: its bytes, media type, ETag and, if time changes it, its last second."""

    body: bytes
    media_type: str
    etag: str
    expires: float | None = None  # time.time() after which the body is out of date
    gzipped: bool = False

    @classmethod
    def of(cls, body: bytes, media_type: str, expires: float | None = None) -> Prepared:
        """A body with a weak ETag drawn from its bytes."""
        digest = hashlib.blake2b(body, digest_size=12).hexdigest()
        return cls(body, media_type, f'W/"{digest}"', expires)

    @property
    def size(self) -> int:
        """Bytes held."""
        return len(self.body)


class ReadCache:
    """A thread-safe LRU of :class:`Prepared` answers, bounded in entries and bytes."""

    def __init__(self, max_items: int = 2048, max_bytes: int = 64 * 1024 * 1024) -> None:
        self.max_items, self.max_bytes = max_items, max_bytes
        self._items: OrderedDict[Hashable, Prepared] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def get(self, key: Hashable) -> Prepared | None:
        """The answer stored under ``key`` if it is still in date."""
        with self._lock:
            item = self._items.get(key)
            if item is None:
                return None
            if item.expires is not None and time.time() >= item.expires:
                self._bytes -= self._items.pop(key).size
                return None
            self._items.move_to_end(key)
            return item

    def put(self, key: Hashable, item: Prepared) -> None:
        """Store ``item`` (not at all when it alone is over the byte bound)."""
        if item.size > self.max_bytes:
            return
        with self._lock:
            old = self._items.pop(key, None)
            self._bytes += item.size - (old.size if old else 0)
            self._items[key] = item
            while len(self._items) > self.max_items or self._bytes > self.max_bytes:
                self._bytes -= self._items.popitem(last=False)[1].size

    def clear(self) -> None:
        """Forget everything."""
        with self._lock:
            self._items.clear()
            self._bytes = 0


async def prepared(
    request: Request,
    key: Hashable,
    build: Callable[[], Prepared | None],
    gate: asyncio.Semaphore | None = None,
) -> Prepared | None:
    """The cached answer for ``key``, else ``build()`` run in the thread pool and stored.

    With a ``gate``, builds wait for it (a request that waited may then find its answer
    built), so queries whose parameters each miss the cache take at most that many threads.
    """
    cache: ReadCache = request.app.state.read_cache
    item = cache.get(key)
    if item is None and gate is not None:
        async with gate:
            return await prepared(request, key, build)
    if item is None:
        item = await run_in_threadpool(build)
        if item is not None:
            cache.put(key, item)
    return item


def not_modified(request: Request, etag: str) -> bool:
    """True when the request's ``If-None-Match`` names ``etag`` (weak comparison)."""
    header = request.headers.get("if-none-match")
    if not header:
        return False
    if header.strip() == "*":
        return True
    bare = etag.removeprefix("W/")
    return any(tag.strip().removeprefix("W/") == bare for tag in header.split(","))


def answer(request: Request, item: Prepared, cache_control: str = NO_CACHE) -> Response:
    """``item`` as a response, or 304 when the client has it already."""
    headers = {"ETag": item.etag, "Cache-Control": cache_control}
    if item.gzipped:
        headers["Vary"] = "Accept-Encoding"
    if not_modified(request, item.etag):
        return Response(status_code=304, headers=headers)
    return Response(item.body, media_type=item.media_type, headers=headers)


def accepts_gzip(request: Request) -> bool:
    """True when the client's ``Accept-Encoding`` allows gzip."""
    for part in request.headers.get("accept-encoding", "").lower().split(","):
        coding, _, params = part.strip().partition(";")
        if coding.strip() in ("gzip", "*") and params.replace(" ", "") not in ("q=0", "q=0.0"):
            return True
    return False


def gzip_prepared(data: bytes, media_type: str, etag: str) -> Prepared:
    """``data`` compressed once, to be served as is to clients that accept gzip."""
    return Prepared(gzip.compress(data, 6, mtime=0), media_type, etag, gzipped=True)


def inflated(item: Prepared) -> Prepared:
    """The identity copy of a gzip-stored ``item``: its bytes inflated, the same ETag."""
    return Prepared(gzip.decompress(item.body), item.media_type, item.etag)


async def answer_gzipped(
    request: Request,
    key: Hashable,
    build: Callable[[], Prepared],
    cache_control: str = IMMUTABLE,
) -> Response:
    """A body kept gzip-compressed (``build`` makes it, e.g. with :func:`gzip_prepared`):
    its bytes to clients that accept gzip; for the others its inflated copy, made in the
    thread pool once and cached beside it (never inflated on the event loop).

    The two encodings carry different strong tags (``"sha"`` and ``"sha.gz"``); either one
    in ``If-None-Match`` answers 304.
    """
    item = await prepared(request, key, build)
    assert item is not None
    gz = accepts_gzip(request)
    etag = item.etag[:-1] + '.gz"' if gz else item.etag
    headers = {"ETag": etag, "Cache-Control": cache_control, "Vary": "Accept-Encoding"}
    if not_modified(request, item.etag) or not_modified(request, item.etag[:-1] + '.gz"'):
        return Response(status_code=304, headers=headers)
    if gz:
        headers["Content-Encoding"] = "gzip"
        return Response(item.body, media_type=item.media_type, headers=headers)
    plain = await prepared(request, ("identity", key), lambda: inflated(item))
    assert plain is not None
    return Response(plain.body, media_type=plain.media_type, headers=headers)


class DriverQuery:
    """A fixed ``SELECT`` compiled once per dialect and run on the driver's own cursor.

    The version reads run before every public read, so they skip what SQLAlchemy does per
    execution (building the statement, its cache key, the result object): a plain cursor
    from the engine's pool, the compiled SQL and its parameters, one row back.
    """

    def __init__(self, statement: Select) -> None:
        self.statement = statement
        self._compiled: dict[str, tuple[str, dict[str, Any], tuple[str, ...] | None]] = {}

    def _for(self, dialect: Dialect) -> tuple[str, dict[str, Any], tuple[str, ...] | None]:
        found = self._compiled.get(dialect.name)
        if found is None:
            compiled = self.statement.compile(dialect=dialect)
            order = tuple(compiled.positiontup) if compiled.positional else None
            found = self._compiled[dialect.name] = (compiled.string, compiled.params, order)
        return found

    def first(self, engine: Engine, **params: Any) -> tuple[Any, ...] | None:
        """The first row for ``params`` (the statement's bind parameters by name), or None."""
        sql, defaults, order = self._for(engine.dialect)
        values = {**defaults, **params}
        args = tuple(values[name] for name in order) if order is not None else values
        connection = engine.raw_connection()
        driver = connection.driver_connection
        autocommit = engine.dialect.name == "postgresql"  # no BEGIN and ROLLBACK round trips
        try:
            if autocommit:
                driver.autocommit = True  # type: ignore[union-attr]
            cursor = connection.cursor()
            try:
                cursor.execute(sql, args)
                return cursor.fetchone()
            finally:
                cursor.close()
        finally:
            if autocommit:
                driver.autocommit = False  # type: ignore[union-attr]
            connection.close()  # back to the pool


def _engine(request: Request) -> Engine:
    return request.app.state.engine


EVENT_VERSION = DriverQuery(select(Event.results_version).where(Event.id == bindparam("event_id")))
LEAGUE_VERSION = DriverQuery(
    select(
        func.count(Event.id),
        func.coalesce(func.max(Event.id), 0),
        func.coalesce(func.sum(Event.results_version), 0),
    )
)
RACE_VERSION = DriverQuery(
    select(Race.event_id, Event.results_version, Race.trace_sha256)
    .join(Event, Race.event_id == Event.id)
    .where(Race.id == bindparam("race_id"))
)


def event_version(request: Request, event_id: int) -> int | None:
    """The event's ``results_version`` (None: no such event); one primary-key read."""
    row = EVENT_VERSION.first(_engine(request), event_id=event_id)
    return None if row is None else row[0]


def league_version(request: Request) -> tuple[int, int, int]:
    """What changes whenever any event is added or any event's results change: the count
    and highest id of events and the sum of their ``results_version``."""
    row = LEAGUE_VERSION.first(_engine(request))
    assert row is not None
    count, top, total = row
    return int(count), int(top), int(total)


def race_version(request: Request, race_id: int) -> tuple[int, int, str | None] | None:
    """The race's event id, that event's ``results_version`` and the race's trace digest
    (None: no such race); one indexed join."""
    row = RACE_VERSION.first(_engine(request), race_id=race_id)
    return None if row is None else (row[0], row[1], row[2])
