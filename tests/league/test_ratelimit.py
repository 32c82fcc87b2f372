"""Rate limiting: the token bucket and a live server answering 429."""

from __future__ import annotations

import httpx

from league.app import create_app
from league.ratelimit import TokenBucket
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
