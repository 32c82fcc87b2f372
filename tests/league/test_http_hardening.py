"""HTTP hardening on a real server: per-route body caps (413), body deadlines (408) and the
security headers every response carries, with ``/docs`` served from this server alone.
How soon the refusals come is measured by ``benchmarks/body_flood.py``.
"""

from __future__ import annotations

import html
import re
import secrets
import select
import socket
import time
from collections.abc import Iterator
from dataclasses import dataclass
from urllib.parse import urljoin, urlsplit

import pytest

from league.http.security import CONTENT_SECURITY_POLICY
from tests.league.conftest import UPLOAD_LIMIT, Database, League, start_league
from tests.league.helpers import car, create_event, enter, record, upload

BODY_TIMEOUT_S = 1.0
UPLOAD_TIMEOUT_S = 2.0
MAX_BODY = 16 * 1024
ENTRY_ROUTE = "/api/events/1/entries"
# Only a bound on a hung server: 15 times the longest deadline waited for here.
HANG_GUARD_S = 30.0
# A trickled body takes 0.1 s a byte: 300 bytes outlast either deadline at least 15 times.
TRICKLE_S = 0.1
TRICKLED = 300


@pytest.fixture(scope="module")
def league(database: Database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """A league whose body deadlines are short enough to wait for in a test."""
    yield from start_league(
        database,
        tmp_path_factory.mktemp("hardening") / "data",
        body_timeout_seconds=BODY_TIMEOUT_S,
        upload_timeout_seconds=UPLOAD_TIMEOUT_S,
    )


@dataclass(frozen=True)
class Answer:
    """What the server answered a raw request, and when."""

    status: int
    text: str
    seconds: float  # from just before the head was sent to the answer's arrival
    sent: int  # body bytes the client had sent by then


def raw_request(league: League, head: str, body: bytes = b"", trickle_s: float = 0.0) -> Answer:
    """Send ``head``, then ``body`` (one byte per ``trickle_s`` if set) on a raw socket.

    Stops sending once the server answers, then reads the answer up to the server's close.
    """
    url = urlsplit(league.url)
    with socket.create_connection((url.hostname, url.port), timeout=HANG_GUARD_S) as sock:
        start = time.monotonic()
        sock.sendall(head.encode())
        sent = 0
        if not trickle_s:
            sock.sendall(body)
            sent = len(body)
        while trickle_s and sent < len(body) and not select.select([sock], [], [], trickle_s)[0]:
            sock.sendall(body[sent : sent + 1])
            sent += 1
        assert select.select([sock], [], [], HANG_GUARD_S)[0], "the server never answered"
        seconds = time.monotonic() - start
        answer = b""
        try:
            while chunk := sock.recv(65536):
                answer += chunk
        except ConnectionResetError:
            pass  # closed with a byte of ours unread: a reset is a close too
    status = int(answer.split(b" ", 2)[1])
    return Answer(status, answer.decode(errors="replace"), seconds, sent)


def json_head(path: str, length: int) -> str:
    return (
        f"POST {path} HTTP/1.1\r\nHost: league\r\nContent-Type: application/json\r\n"
        f"Content-Length: {length}\r\nConnection: close\r\n\r\n"
    )


def test_a_json_body_over_the_small_cap_is_refused_before_it_is_read(league: League) -> None:
    answer = raw_request(league, json_head(ENTRY_ROUTE, 50_000_000))
    assert answer.status == 413 and f"limit of {MAX_BODY} bytes" in answer.text
    assert answer.sent == 0  # answered on the head alone: not one byte of the 50 MB was sent


def test_json_bodies_over_the_cap_get_413_with_or_without_a_length(league: League) -> None:
    padding = {"model_id": 1, "pad": "x" * (200 * 1024)}
    chunks = [b'{"model_id": 1, "pad": "', b"x" * 200 * 1024, b'"}']
    with league.client() as anonymous, league.client("alice") as alice:
        declared = anonymous.post(ENTRY_ROUTE, json=padding)
        chunked = anonymous.post(ENTRY_ROUTE, content=iter(chunks))
        bad_token = anonymous.post(
            "/api/events", json=padding, headers={"Authorization": "Bearer nobody"}
        )
        racer = alice.post(ENTRY_ROUTE, json=padding)
        small = alice.post(ENTRY_ROUTE, json={"model_id": 1})
    for response in (declared, chunked, bad_token, racer):
        assert response.status_code == 413, response.text
        assert f"limit of {MAX_BODY} bytes" in response.json()["detail"]
    assert small.status_code == 404  # under the cap the route itself answers


def test_the_upload_route_keeps_the_upload_cap(league: League) -> None:
    junk = secrets.token_bytes(100 * 1024)  # over the JSON cap, under the upload cap
    too_big = secrets.token_bytes(UPLOAD_LIMIT + 128 * 1024)
    with league.client("alice") as alice:
        judged = alice.post("/api/models", files={"file": ("junk.zip", junk)})
        refused = alice.post("/api/models", files={"file": ("big.zip", too_big)})
    assert judged.status_code == 422, judged.text  # read and judged by the validator
    assert refused.status_code == 413
    assert str(UPLOAD_LIMIT + 64 * 1024) in refused.json()["detail"]


# The server's deadline starts once it has the head, after the client's clock started; but
# uvloop's clock counts whole milliseconds, cached per loop iteration, so the deadline may
# fire a millisecond or two before the client's clock says it is due.
CLOCK_SLACK_S = 0.01


def test_a_body_that_trickles_in_gets_408_at_its_routes_deadline(league: League) -> None:
    """Cut off by the server (408, then its close) while the body was still coming, and no
    sooner than the route's deadline."""
    answer = raw_request(
        league, json_head(ENTRY_ROUTE, TRICKLED), b" " * TRICKLED, trickle_s=TRICKLE_S
    )
    assert answer.status == 408 and f"within {BODY_TIMEOUT_S:g} s" in answer.text
    assert answer.sent < TRICKLED
    assert answer.seconds >= BODY_TIMEOUT_S - CLOCK_SLACK_S

    part = b'--b\r\nContent-Disposition: form-data; name="file"; filename="m.zip"\r\n\r\n'
    head = (
        "POST /api/models HTTP/1.1\r\nHost: league\r\n"
        "Content-Type: multipart/form-data; boundary=b\r\n"
        f"Content-Length: {len(part) + TRICKLED}\r\nConnection: close\r\n\r\n"
    )
    body = b"z" * TRICKLED
    answer = raw_request(league, head + part.decode(), body, trickle_s=TRICKLE_S)
    assert answer.status == 408 and f"within {UPLOAD_TIMEOUT_S:g} s" in answer.text
    assert answer.sent < TRICKLED
    assert answer.seconds >= UPLOAD_TIMEOUT_S - CLOCK_SLACK_S


def assert_security_headers(headers: object, where: str) -> None:
    """The headers every response must carry."""
    assert headers.get("content-security-policy") == CONTENT_SECURITY_POLICY, where
    assert "frame-ancestors 'none'" in CONTENT_SECURITY_POLICY
    assert "script-src 'self'" in CONTENT_SECURITY_POLICY
    assert "unsafe-inline" not in CONTENT_SECURITY_POLICY
    assert headers.get("x-content-type-options") == "nosniff", where
    assert headers.get("x-frame-options") == "DENY", where
    assert headers.get("referrer-policy") == "no-referrer", where


def test_every_page_and_api_answer_carries_the_security_headers(league: League) -> None:
    event = create_event(league, name="Headers Cup")
    model = upload(league, "alice", seed=151)
    entry = enter(league, "alice", event["id"], model["id"])
    race_id = record(league, event["id"], {entry["entry_id"]: car("alice")})
    paths = [
        "/",
        "/upload",
        f"/events/{event['id']}",
        f"/races/{race_id}",
        f"/models/{model['id']}",
        "/docs",
        "/openapi.json",
        "/static/common.js",
        "/api/events",
        "/api/racers/me",  # 401
        "/events/999999",  # 404
        "/healthz",
    ]
    with league.client() as client:
        for path in paths:
            response = client.get(path)
            assert response.status_code < 500, path
            assert_security_headers(response.headers, path)
        refused = client.post(ENTRY_ROUTE, json={"pad": "x" * MAX_BODY})
        assert refused.status_code == 413
        assert_security_headers(refused.headers, "413")


def test_pages_have_no_inline_script(league: League) -> None:
    """Every ``<script>`` has a same-origin ``src`` and no body; no inline handlers."""
    with league.client() as client:
        for path in ("/", "/upload", "/docs"):
            html = client.get(path).text
            for attrs, body in re.findall(r"<script([^>]*)>(.*?)</script>", html, re.S):
                assert "src=" in attrs and not body.strip(), (path, attrs)
            assert not re.search(r"\son[a-z]+\s*=", html), path
            assert not re.search(r"\sstyle\s*=", html), path


def test_docs_are_served_here_and_list_every_route(league: League) -> None:
    with league.client() as client:
        page = client.get("/docs")
        spec = client.get("/openapi.json").json()
        assert page.status_code == 200
        links = re.findall(r'(?:src|href)="([^"#]+)"', page.text)
        fetched = [link for link in links if not link.startswith("data:")]
        assert any(link.endswith(".css") for link in fetched)
        for link in fetched:
            url = urljoin(league.url + "/docs", link)
            assert urlsplit(url).netloc == urlsplit(league.url).netloc, link
            assert client.get(url).status_code == 200, link
        assert client.get("/redoc").status_code == 404
    for path, item in spec["paths"].items():
        for method in item:
            assert f"{method.upper()} {path}" in html.unescape(page.text), (method, path)
