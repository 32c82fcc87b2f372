"""Rate limiting: the token bucket and a live server answering 429, keyed on whom."""

from __future__ import annotations

import asyncio
import ipaddress
import secrets
from typing import Any

import httpx
from sqlalchemy import update

from league import crud
from league.db import make_engine, make_session_factory
from league.http.app import create_app
from league.http.ratelimit import KnownTokens, RateLimitMiddleware, TokenBucket, address_key
from league.migrations import upgrade
from league.models import Racer
from league.settings import Settings
from tests.league.conftest import ServerThread, free_port


def test_bucket_refills() -> None:
    bucket = TokenBucket(rate=2.0, burst=3)
    assert [bucket.take("a", now=0.0) for _ in range(3)] == [0.0, 0.0, 0.0]
    assert bucket.take("a", now=0.0) == 0.5
    assert bucket.take("b", now=0.0) == 0.0
    assert bucket.take("a", now=0.6) == 0.0


def test_server_answers_429_with_retry_after(tmp_path) -> None:
    app = create_app(Settings(data_dir=tmp_path, rate_limit_per_second=1, rate_limit_burst=5))
    with ServerThread(app, free_port()) as server, httpx.Client(base_url=server.url) as client:
        codes = [client.get("/api/racers/me").status_code for _ in range(8)]
        limited = client.get("/api/racers/me")
        health = client.get("/healthz")
    assert codes.count(429) >= 2 and limited.status_code == 429
    assert int(limited.headers["retry-after"]) >= 1 and "Too many" in limited.json()["detail"]
    assert health.status_code == 200


def test_random_tokens_share_the_address_bucket_and_racers_keep_theirs(tmp_path) -> None:
    """Unknown bearer tokens are charged to the client address; a checked-out token to its racer."""
    settings = Settings(data_dir=tmp_path, rate_limit_per_second=0.01, rate_limit_burst=20)
    engine = make_engine(settings.db_url)
    upgrade(engine)
    sessions = make_session_factory(engine)
    with sessions() as session:
        racer, token = crud.create_racer(session, "alice")
        racer_id = racer.id
    alice = {"Authorization": f"Bearer {token}"}
    app = create_app(settings)
    with ServerThread(app, free_port()) as server, httpx.Client(base_url=server.url) as client:
        assert client.get("/api/racers/me", headers=alice).status_code == 200
        random_codes = [
            client.get(
                "/api/racers/me", headers={"Authorization": f"Bearer {secrets.token_urlsafe(32)}"}
            ).status_code
            for _ in range(40)
        ]
        anonymous = client.get("/api/events").status_code
        alice_again = client.get("/api/racers/me", headers=alice).status_code
        with sessions() as session:  # the token stops checking out (as after a rotation)
            session.execute(update(Racer).where(Racer.id == racer_id).values(token_hash="0"))
            session.commit()
        alice_stale = client.get("/api/racers/me", headers=alice).status_code
        alice_forgotten = client.get("/api/racers/me", headers=alice).status_code
    app.state.engine.dispose()
    engine.dispose()
    assert random_codes[:19] == [401] * 19  # the address's burst, less alice's first request
    assert set(random_codes[19:]) == {429}
    assert anonymous == 429
    assert alice_again == 200
    assert alice_stale == 401  # still charged to alice, answered by auth
    assert alice_forgotten == 429  # forgotten: back on the exhausted address bucket


def test_a_flood_of_new_keys_evicts_the_least_recent_and_never_resets_a_drained_bucket() -> None:
    """Past the key cap the oldest idle keys go; a client that keeps knocking stays limited."""
    bucket = TokenBucket(rate=0.001, burst=2, max_keys=100)
    assert [bucket.take("attacker", now=0.0) for _ in range(2)] == [0.0, 0.0]
    refused = []
    for i in range(1_000):
        bucket.take(f"flood-{secrets.token_hex(8)}-{i}", now=0.0)
        if i % 10 == 0:
            refused.append(bucket.take("attacker", now=0.0))
    assert all(wait > 0.0 for wait in refused)
    assert len(bucket) == 100


def test_known_tokens_are_evicted_least_recent_first() -> None:
    known = KnownTokens(max_keys=50)
    known.remember("alice", 1)
    for i in range(500):
        known.remember(secrets.token_hex(16), 1_000 + i)
        assert known.racer("alice") == 1  # in use, so never the one evicted


def _scope(host: str) -> dict[str, Any]:
    return {"type": "http", "path": "/api/events", "headers": [], "client": (host, 50_000)}


def _codes_through_middleware(hosts: list[str], burst: int) -> list[int]:
    """Status codes of one request from each host, through a real RateLimitMiddleware."""

    async def ok(scope: Any, receive: Any, send: Any) -> None:
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b""})

    limiter = RateLimitMiddleware(ok, rate=0.001, burst=burst)

    async def run() -> list[int]:
        codes = []
        for host in hosts:
            sent: list[dict[str, Any]] = []

            async def send(message: dict[str, Any], sent: list = sent) -> None:
                sent.append(message)

            await limiter(_scope(host), None, send)
            codes.append(sent[0]["status"])
        return codes

    return asyncio.run(run())


def test_ipv6_clients_share_the_bucket_of_their_64() -> None:
    """Addresses rotated within one /64 (one subscriber's block) are one client."""
    prefix = ipaddress.IPv6Network("2001:db8:77:1::/64")
    rotated = [str(prefix[secrets.randbits(64)]) for _ in range(60)]
    codes = _codes_through_middleware(rotated, burst=20)
    assert codes[:20] == [200] * 20 and set(codes[20:]) == {429}
    neighbours = [f"2001:db8:77:{n:x}::1" for n in range(2, 32)]  # other /64s: other clients
    assert set(_codes_through_middleware(neighbours, burst=1)) == {200}
    assert address_key(_scope("::ffff:192.0.2.7")) == address_key(_scope("192.0.2.7"))
    assert address_key(_scope("192.0.2.7")) != address_key(_scope("192.0.2.8"))
