"""Rate limiting: the token bucket and a live server answering 429, keyed on whom."""

from __future__ import annotations

import secrets

import httpx
from sqlalchemy import update

from league import crud
from league.db import make_engine, make_session_factory
from league.http.app import create_app
from league.http.ratelimit import TokenBucket
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
