"""Cached public reads: ETag / 304, never stale after a result, immutable gzip traces,
thumbnails drawn once, and two server processes that both see a new result.

Runs on the module's real uvicorn server (SQLite, and PostgreSQL when configured); the
two-worker test starts ``slipstream league serve --workers 2`` on the same database.
"""

from __future__ import annotations

import gzip
import os
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from league.http.read_cache import Prepared, ReadCache
from league.web import queries
from tests.league.conftest import League, free_port
from tests.league.helpers import car, create_event, enter, record, upload
from tests.league.page_text import read_page

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def cup(league: League) -> dict[str, int]:
    """An event with alice's and bob's models entered and one race of alice's."""
    event = create_event(league, name="Cache Cup", seeds=[0, 1])["id"]
    ids = {"event": event}
    for who, seed in (("alice", 31), ("bob", 32)):
        model = upload(league, who, seed)["id"]
        ids[who] = enter(league, who, event, model)["entry_id"]
    ids["race"] = record(league, event, {ids["alice"]: car("alice", laps=[9.0, 9.0])}, seed=0)
    return ids


def public_reads(ids: dict[str, int]) -> list[str]:
    """Every public read that changes with results."""
    event, race = ids["event"], ids["race"]
    return [
        "/",
        f"/events/{event}",
        f"/api/events/{event}/leaderboard",
        f"/api/races?event={event}&limit=20",
        "/api/races",
        f"/api/races/{race}",
        f"/races/{race}",
    ]


def test_each_public_read_has_an_etag_and_answers_304(league: League, cup: dict) -> None:
    with league.client() as client:
        for path in public_reads(cup):
            first = client.get(path)
            assert first.status_code == 200, path
            etag = first.headers["etag"]
            assert first.headers["cache-control"] == "no-cache", path
            again = client.get(path, headers={"If-None-Match": etag})
            assert again.status_code == 304, path
            assert again.content == b"" and again.headers["etag"] == etag
            assert "content-security-policy" in again.headers
            other = client.get(path, headers={"If-None-Match": 'W/"something-else"'})
            assert other.status_code == 200 and other.content == first.content


def test_a_recorded_result_changes_etag_and_body(league: League, cup: dict) -> None:
    event = cup["event"]
    paths = [f"/api/events/{event}/leaderboard", f"/api/races?event={event}", "/api/races"]
    with league.client() as client:
        before = {p: client.get(p) for p in paths}
        race = record(league, event, {cup["bob"]: car("bob", laps=[8.0, 8.0])}, seed=0)
        for path in paths:
            after = client.get(path, headers={"If-None-Match": before[path].headers["etag"]})
            assert after.status_code == 200, path
            assert after.headers["etag"] != before[path].headers["etag"]
            assert after.content != before[path].content
        board = client.get(f"/api/events/{event}/leaderboard").json()
        races = client.get(f"/api/races?event={event}").json()
    assert board["rows"][0]["alias"] == "bob" and board["rows"][0]["best_lap_ms"] == 8000
    assert races[0]["id"] == race


def head_to_head_rows(client: httpx.Client, event: int) -> list[list[str]]:
    """The head-to-head table of the event's page, as read: one row of cell texts each."""
    response = client.get(f"/events/{event}")
    assert response.status_code == 200
    return read_page(response.text).tables["head-to-head"]


def test_pages_show_each_new_result(league: League, cup: dict) -> None:
    event = create_event(league, name="Cache Duel", race_type="head_to_model")["id"]
    entries = {}
    for who, seed in (("alice", 34), ("bob", 35)):
        model = upload(league, who, seed, name=f"{who}-duel")["id"]
        entries[who] = enter(league, who, event, model)["entry_id"]
    slow = [12.0, 12.0, 12.0]
    alice, bob = "alice · alice-duel", "bob · bob-duel"
    with league.client() as client:
        assert head_to_head_rows(client, event) == [["No races yet."]]
        cars = {entries["alice"]: car("alice")}
        cars[entries["bob"]] = car("bob", laps=slow, finish_position=2)
        first = record(league, event, cars, seed=1)
        assert head_to_head_rows(client, event) == [[alice, "1", "0", bob, "1", "0 / 0"]]
        before = {p: client.get(p) for p in (f"/races/{first}", f"/api/races/{first}")}

        cars = {entries["alice"]: car("alice", laps=slow, finish_position=2)}
        cars[entries["bob"]] = car("bob", laps=[8.0, 8.0, 8.0])
        second = record(league, event, cars, seed=2)
        assert head_to_head_rows(client, event) == [[alice, "1", "1", bob, "2", "0 / 0"]]
        page = read_page(client.get(f"/races/{second}").text)
        assert f"Cache Duel › race {second} (seed 2)" in page.text
        shown = client.get(f"/api/races/{second}").json()
        for path, response in before.items():  # an earlier race is as it was
            again = client.get(path, headers={"If-None-Match": response.headers["etag"]})
            assert again.status_code == 304, path
    winner = {c["alias"]: c for c in shown["cars"]}["bob"]
    assert (shown["id"], winner["finish_position"], winner["best_ms"]) == (second, 1, 8000)
    assert f"Cache Duel › race {first} (seed 1)" in read_page(before[f"/races/{first}"].text).text


def test_a_new_entry_changes_the_home_page(league: League, cup: dict) -> None:
    with league.client() as client:
        before = client.get("/")
        event = create_event(league, name="Late Cup", seeds=[0])["id"]
        after = client.get("/", headers={"If-None-Match": before.headers["etag"]})
        assert after.status_code == 200 and "Late Cup" in after.text
        model = upload(league, "alice", 33)["id"]
        enter(league, "alice", event, model)
        entered = client.get("/", headers={"If-None-Match": after.headers["etag"]})
    assert entered.status_code == 200 and entered.headers["etag"] != after.headers["etag"]


def test_traces_are_immutable_and_gzipped_when_asked(league: League, cup: dict) -> None:
    path = f"/api/races/{cup['race']}/trace"
    with league.sessions() as session:
        from league.models import Race

        stored = league.storage.read("traces", session.get_one(Race, cup["race"]).trace_sha256)
    with league.client() as client:
        zipped = client.get(path, headers={"Accept-Encoding": "gzip"})
        plain = client.get(path, headers={"Accept-Encoding": "identity"})
        assert zipped.status_code == plain.status_code == 200
        for response in (zipped, plain):
            assert response.headers["cache-control"] == "public, max-age=31536000, immutable"
            assert response.headers["vary"] == "Accept-Encoding"
        assert zipped.headers["content-encoding"] == "gzip"
        assert "content-encoding" not in plain.headers
        assert zipped.content == plain.content == stored  # httpx inflates gzip
        for response in (zipped, plain):
            again = client.get(path, headers={"If-None-Match": response.headers["etag"]})
            assert again.status_code == 304
    with (
        httpx.Client(base_url=league.url) as raw,
        raw.stream("GET", path, headers={"Accept-Encoding": "gzip"}) as response,
    ):
        body = b"".join(response.iter_raw())
    assert gzip.decompress(body) == stored


def test_thumbnails_are_drawn_once_per_track_and_direction(
    league: League, cup: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[str] = []
    draw = queries.track_thumbnail_svg

    def counting(track: object, size: int = 120) -> str:
        calls.append(f"{track.name}:{track.direction}")  # type: ignore[attr-defined]
        return draw(track, size=size)  # type: ignore[arg-type]

    monkeypatch.setattr(queries, "track_thumbnail_svg", counting)
    monkeypatch.setattr(queries, "_THUMBNAILS", {})
    with league.client() as client:
        create_event(league, name="Another Cup", seeds=[0])  # the home page is rebuilt
        assert "Another Cup" in client.get("/").text
        drawn = len(calls)
        assert drawn >= 1 and len(set(calls)) == drawn
        create_event(league, name="Third Cup", seeds=[0])  # rebuilt again, same tracks
        assert "Third Cup" in client.get("/").text
        assert client.get(f"/events/{cup['event']}").status_code == 200
    assert len(calls) == drawn


def test_read_cache_bounds_and_expiry() -> None:
    cache = ReadCache(max_items=2, max_bytes=10)
    cache.put("a", Prepared.of(b"1234", "text/plain"))
    cache.put("b", Prepared.of(b"1234", "text/plain"))
    cache.put("c", Prepared.of(b"1234", "text/plain"))
    assert cache.get("a") is None and cache.get("c") is not None
    cache.put("big", Prepared.of(b"x" * 11, "text/plain"))
    assert cache.get("big") is None
    cache.put("old", Prepared.of(b"1", "text/plain", expires=time.time() - 1))
    assert cache.get("old") is None
    assert Prepared.of(b"x", "a").etag == Prepared.of(b"x", "b").etag != Prepared.of(b"y", "a").etag


def _serve(league: League, port: int, workers: int) -> subprocess.Popen:
    env = {
        **os.environ,
        "SLIPSTREAM_DATABASE_URL": league.settings.db_url,
        "SLIPSTREAM_DATA_DIR": str(league.settings.data_dir),
        "SLIPSTREAM_RATE_LIMIT_PER_SECOND": "0",
    }
    args = ["serve", "--port", str(port), "--workers", str(workers), "--no-access-log"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "league", *args],
        env=env,
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        try:
            if httpx.get(f"http://127.0.0.1:{port}/healthz").status_code == 200:
                return proc
        except httpx.TransportError:
            time.sleep(0.2)
    proc.terminate()
    raise RuntimeError("the league server did not start")


def test_two_workers_both_serve_a_new_result(league: League, cup: dict) -> None:
    port = free_port()
    proc = _serve(league, port, workers=2)
    event = cup["event"]
    path = f"http://127.0.0.1:{port}/api/events/{event}/leaderboard"
    try:
        children = subprocess.run(
            ["ps", "-o", "pid=", "--ppid", str(proc.pid)], capture_output=True, text=True
        ).stdout.split()
        assert len(children) >= 2  # the supervisor's two worker processes

        def fresh() -> httpx.Response:  # a new connection each time, so both workers answer
            with httpx.Client(headers={"Connection": "close"}) as client:
                return client.get(path)

        before = [fresh() for _ in range(30)]  # both processes cache this version
        assert len({r.headers["etag"] for r in before}) == 1
        record(league, event, {cup["alice"]: car("alice", laps=[7.0, 7.0])}, seed=1)
        after = [fresh() for _ in range(30)]
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert all(r.status_code == 200 for r in before + after)
    assert {r.headers["etag"] for r in after} == {after[0].headers["etag"]}
    assert after[0].headers["etag"] != before[0].headers["etag"]
    assert all(r.json()["rows"][0]["best_lap_ms"] == 7000 for r in after)
