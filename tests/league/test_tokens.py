"""A leaked token: racers rotate their own (``POST /api/racers/me/token``), admins rotate or
revoke anyone's from the server host (``slipstream league rotate-token`` / ``revoke-token``).
Real server, SQLite and PostgreSQL; the CLI works on the same database."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest
from typer.testing import CliRunner

from league.cli import app
from tests.league.conftest import League

runner = CliRunner()


def _me(league: League, token: str) -> int:
    """The status of ``GET /api/racers/me`` with ``token``."""
    headers = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=league.url, headers=headers, timeout=30) as client:
        return client.get("/api/racers/me").status_code


def _new_racer(league: League, alias: str) -> str:
    """Create ``alias`` through the API as admin; their token."""
    with league.client("admin") as admin:
        response = admin.post("/api/racers", json={"alias": alias})
    assert response.status_code == 201, response.text
    assert response.headers["cache-control"] == "no-store"
    return response.json()["token"]


def _rotate_own(league: League, token: str) -> httpx.Response:
    headers = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=league.url, headers=headers, timeout=30) as client:
        return client.post("/api/racers/me/token")


def _cli(league: League, monkeypatch: pytest.MonkeyPatch, *args: str):
    """Run ``slipstream league ARGS`` on the server's data dir and database."""
    monkeypatch.setenv("SLIPSTREAM_DATABASE_URL", league.settings.db_url)
    return runner.invoke(app, [*args, "--data-dir", str(league.settings.data_dir)])


def test_a_racer_rotates_their_own_token(league: League) -> None:
    old = _new_racer(league, "leaky")
    rotated = _rotate_own(league, old)
    assert rotated.status_code == 200, rotated.text
    assert rotated.headers["cache-control"] == "no-store"
    body = rotated.json()
    assert body["alias"] == "leaky" and body["token"] != old
    assert _me(league, old) == 401
    assert _me(league, body["token"]) == 200
    assert _rotate_own(league, old).status_code == 401
    with league.client() as anonymous:
        assert anonymous.post("/api/racers/me/token").status_code == 401


def test_one_token_rotated_twice_at_once_yields_one_new_token(league: League) -> None:
    old = _new_racer(league, "racy")
    with ThreadPoolExecutor(8) as pool:
        answers = list(pool.map(lambda _: _rotate_own(league, old), range(8)))
    statuses = sorted(a.status_code for a in answers)
    assert statuses == [200] + [401] * 7, statuses
    (winner,) = (a.json()["token"] for a in answers if a.status_code == 200)
    assert _me(league, winner) == 200 and _me(league, old) == 401


def test_an_admin_rotates_a_token_from_the_cli(
    league: League, monkeypatch: pytest.MonkeyPatch
) -> None:
    old = _new_racer(league, "carol")
    done = _cli(league, monkeypatch, "rotate-token", "carol")
    assert done.exit_code == 0, done.output
    new = done.output.strip().splitlines()[-1]
    assert len(new) >= 40 and new != old
    assert _me(league, old) == 401
    assert _me(league, new) == 200


def test_a_revoked_token_stays_refused_until_an_admin_rotates_it(
    league: League, monkeypatch: pytest.MonkeyPatch
) -> None:
    token = _new_racer(league, "dave")
    revoked = _cli(league, monkeypatch, "revoke-token", "dave")
    assert revoked.exit_code == 0, revoked.output
    assert "revoked" in revoked.output
    assert _me(league, token) == 401
    assert _rotate_own(league, token).status_code == 401
    again = _cli(league, monkeypatch, "rotate-token", "dave")
    assert again.exit_code == 0, again.output
    assert _me(league, again.output.strip().splitlines()[-1]) == 200
    assert _me(league, token) == 401


@pytest.mark.parametrize("command", ["rotate-token", "revoke-token"])
def test_an_unknown_alias_is_a_clear_error(
    league: League, monkeypatch: pytest.MonkeyPatch, command: str
) -> None:
    result = _cli(league, monkeypatch, command, "nobody")
    assert result.exit_code == 1
    assert "No racer has the alias 'nobody'" in result.output
