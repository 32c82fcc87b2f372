"""Race reads a stranger can make costly (issue 34, rows 8 and 10): a trace read without
gzip is inflated off the event loop and once, not per request; the race list's offset is
capped (422), deeper pages go by keyset (``before``), and lists that each miss the cache
are built one at a time.

Runs on the module's real uvicorn server (SQLite, and PostgreSQL when configured).
"""

from __future__ import annotations

import asyncio
import gzip
import threading
import time

import pytest

from league.http import read_cache
from league.http.routes import races as races_route
from league.http.routes.races import MAX_OFFSET
from league.models import Race
from tests.league.conftest import League
from tests.league.helpers import car, create_event, enter, record, upload


@pytest.fixture(scope="module")
def races(league: League) -> dict[str, object]:
    """An event with four races of alice's model, the newest first."""
    event = create_event(league, name="Paging Cup", seeds=[0, 1, 2, 3])["id"]
    model = upload(league, "alice", 41)["id"]
    entry = enter(league, "alice", event, model)["entry_id"]
    ids = [
        record(league, event, {entry: car("alice", laps=[9.0 + seed])}, seed=seed)
        for seed in range(4)
    ]
    return {"event": event, "ids": sorted(ids, reverse=True)}


def test_identity_trace_reads_inflate_once_and_off_the_event_loop(
    league: League, races: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[bool] = []  # per inflation: was it on the event loop's thread?
    inflate = gzip.decompress

    def watched(data: bytes) -> bytes:
        try:
            asyncio.get_running_loop()
            calls.append(True)
        except RuntimeError:
            calls.append(False)
        return inflate(data)

    monkeypatch.setattr(read_cache.gzip, "decompress", watched)
    race = races["ids"][0]
    with league.sessions() as session:
        stored = league.storage.read("traces", session.get_one(Race, race).trace_sha256)
    path = f"/api/races/{race}/trace"

    def read() -> None:
        with league.client() as client:
            for _ in range(5):
                response = client.get(path, headers={"Accept-Encoding": "identity"})
                assert response.status_code == 200
                assert "content-encoding" not in response.headers
                assert response.content == stored

    readers = [threading.Thread(target=read) for _ in range(4)]
    for reader in readers:
        reader.start()
    for reader in readers:
        reader.join()
    assert calls and not any(calls), "a trace was inflated on the event loop"
    assert len(calls) <= len(readers)  # once, or once per reader that raced the first


def test_a_deep_offset_is_refused_with_a_clear_422(league: League, races: dict) -> None:
    with league.client() as client:
        deep = client.get("/api/races", params={"limit": 500, "offset": MAX_OFFSET + 1})
        edge = client.get("/api/races", params={"limit": 500, "offset": MAX_OFFSET})
        huge = client.get("/api/races", params={"offset": 2**31 - 1})
    assert deep.status_code == huge.status_code == 422
    assert "offset" in deep.json()["detail"] and str(MAX_OFFSET) in deep.json()["detail"]
    assert edge.status_code == 200 and edge.json() == []


def test_before_pages_through_races_newest_first(league: League, races: dict) -> None:
    event, ids = races["event"], races["ids"]
    pages, before = [], None
    with league.client() as client:
        for _ in range(len(ids) + 1):  # a guard: a server ignoring before pages forever
            params = {"event": event, "limit": 3} | ({"before": before} if before else {})
            page = [race["id"] for race in client.get("/api/races", params=params).json()]
            if not page:
                break
            pages.append(page)
            before = page[-1]
        by_offset = client.get("/api/races", params={"event": event, "limit": 3, "offset": 3})
    assert pages == [ids[:3], ids[3:]]
    assert [race["id"] for race in by_offset.json()] == ids[3:]


def test_race_lists_that_miss_the_cache_are_built_one_at_a_time(
    league: League, races: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    running, most = [0], [0]
    lock = threading.Lock()
    build = races_route._race_list

    def watched(*args: object) -> object:
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        try:
            time.sleep(0.05)  # long enough for the other requests to arrive meanwhile
            return build(*args)  # type: ignore[arg-type]
        finally:
            with lock:
                running[0] -= 1

    monkeypatch.setattr(races_route, "_race_list", watched)
    statuses: list[int] = []

    def read(offset: int) -> None:  # a stranger's varied offsets: each one a cache miss
        with league.client() as client:
            params = {"event": races["event"], "limit": 2, "offset": 100 + offset}
            statuses.append(client.get("/api/races", params=params).status_code)

    readers = [threading.Thread(target=read, args=(i,)) for i in range(6)]
    for reader in readers:
        reader.start()
    for reader in readers:
        reader.join()
    assert statuses == [200] * 6
    assert most[0] == 1
