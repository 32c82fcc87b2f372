"""The authorisation matrix: every route x anonymous / owner (alice) / other racer (bob) /
admin. Alice owns a private model, an entered model and that entry's job."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from tests.league.conftest import League, make_model_zip
from tests.league.helpers import car, create_event, enter, record, upload

CALLERS = ("anonymous", "alice", "bob", "admin")


@pytest.fixture(scope="module")
def world(league: League) -> dict[str, Any]:
    """Alice's private model, her entered model, its entry job, an event and a race."""
    event = create_event(league, name="Matrix")
    private = upload(league, "alice", seed=101)
    entered = upload(league, "alice", seed=102)
    entry = enter(league, "alice", event["id"], entered["id"])
    race = record(league, event["id"], {entry["entry_id"]: car("a")})
    spare = [upload(league, "alice", seed=110 + i)["id"] for i in range(4)]
    return {
        "event": event["id"],
        "private": private["id"],
        "entered": entered["id"],
        "job": entry["job_ids"][0],
        "race": race,
        "spare": spare,
    }


def _upload_files(league: League) -> dict[str, Any]:
    path = make_model_zip(league.models_dir, 150)
    return {"files": {"file": (path.name, path.read_bytes())}}


OK_ALL = dict.fromkeys(CALLERS, 200)
AUTHED = {"anonymous": 401, "alice": 200, "bob": 200, "admin": 200}
ADMIN_ONLY = {"anonymous": 401, "alice": 403, "bob": 403, "admin": 201}
OWNER_ONLY = {"anonymous": 404, "alice": 200, "bob": 404, "admin": 200}
OWNER_ONLY_AUTHED = {"anonymous": 401, "alice": 200, "bob": 404, "admin": 200}

# (name, method, path, request kwargs, expected status per caller)
ROUTES: list[tuple[str, str, Callable, Callable, dict[str, int]]] = [
    ("healthz", "GET", lambda w: "/healthz", lambda lg, w, who: {}, OK_ALL),
    ("readyz", "GET", lambda w: "/readyz", lambda lg, w, who: {}, OK_ALL),
    (
        "create racer",
        "POST",
        lambda w: "/api/racers",
        lambda lg, w, who: {"json": {"alias": f"new-{who}"}},
        ADMIN_ONLY,
    ),
    ("me", "GET", lambda w: "/api/racers/me", lambda lg, w, who: {}, AUTHED),
    (
        "upload model",
        "POST",
        lambda w: "/api/models",
        lambda lg, w, who: _upload_files(lg),
        {"anonymous": 401, "alice": 201, "bob": 201, "admin": 201},
    ),
    ("list models", "GET", lambda w: "/api/models", lambda lg, w, who: {}, AUTHED),
    (
        "private model",
        "GET",
        lambda w: f"/api/models/{w['private']}",
        lambda lg, w, who: {},
        OWNER_ONLY,
    ),
    ("entered model", "GET", lambda w: f"/api/models/{w['entered']}", lambda *a: {}, OK_ALL),
    (
        "create event",
        "POST",
        lambda w: "/api/events",
        lambda lg, w, who: {"json": {"name": f"by {who}"}},
        ADMIN_ONLY,
    ),
    ("list events", "GET", lambda w: "/api/events", lambda *a: {}, OK_ALL),
    ("read event", "GET", lambda w: f"/api/events/{w['event']}", lambda *a: {}, OK_ALL),
    (
        "enter alice's model",
        "POST",
        lambda w: f"/api/events/{w['event']}/entries",
        lambda lg, w, who: {"json": {"model_id": w["spare"][CALLERS.index(who)]}},
        {"anonymous": 401, "alice": 202, "bob": 404, "admin": 404},
    ),
    ("read job", "GET", lambda w: f"/api/jobs/{w['job']}", lambda *a: {}, OWNER_ONLY_AUTHED),
    (
        "leaderboard",
        "GET",
        lambda w: f"/api/events/{w['event']}/leaderboard",
        lambda *a: {},
        OK_ALL,
    ),
    ("list races", "GET", lambda w: f"/api/races?event={w['event']}", lambda *a: {}, OK_ALL),
    ("read race", "GET", lambda w: f"/api/races/{w['race']}", lambda *a: {}, OK_ALL),
    ("read trace", "GET", lambda w: f"/api/races/{w['race']}/trace", lambda *a: {}, OK_ALL),
]


@pytest.mark.parametrize("who", CALLERS)
@pytest.mark.parametrize("route", ROUTES, ids=[r[0] for r in ROUTES])
def test_matrix(league: League, world: dict[str, Any], route: tuple, who: str) -> None:
    _name, method, path, kwargs, expected = route
    caller = None if who == "anonymous" else who
    with league.client(caller) as client:
        response = client.request(method, path(world), **kwargs(league, world, who))
    assert response.status_code == expected[who], response.text
    assert response.headers["content-type"].startswith("application/json")
    if response.status_code >= 400:
        assert response.json()["detail"]


def test_other_racers_never_see_private_data(league: League, world: dict[str, Any]) -> None:
    with league.client("bob") as bob:
        listed = bob.get("/api/models").json()
        public = bob.get(f"/api/models/{world['entered']}").json()
    assert all(m["owner"] == "bob" for m in listed)
    assert public["visibility"] == "public"
    assert public["sha256"] is None and public["info"] is None and public["size"] is None


def test_bad_tokens_are_refused(league: League) -> None:
    for header in ("Bearer nonsense", "Bearer", "Basic abc", f"Bearer {league.tokens['alice']}x"):
        with league.client() as client:
            response = client.get("/api/racers/me", headers={"Authorization": header})
        assert response.status_code == 401, header
