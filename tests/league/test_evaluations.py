"""Evaluations: a racer races one of their models alone on any track and direction; the
league's worker races it; the evaluation stays unlisted and takes no other entries."""

from __future__ import annotations

from datetime import timedelta
from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import select, text
from sqlalchemy.exc import IntegrityError

from league.db import make_engine
from league.http.routes.evaluations import evaluation_status
from league.jobs.scheduler import close_events
from league.jobs.worker import Worker
from league.migrations import alembic_config, upgrade
from league.models import Event, utcnow
from tests.league.conftest import Database, League, _postgres_database, start_league
from tests.league.helpers import create_event, upload
from tests.league.page_text import read_page

TRACK, DIRECTION = "hairpin_hollow", "cw"  # the test models were made on beginner_loop, ccw
EVENT = (
    "INSERT INTO events (id, name, race_type, track, direction, ranking_metric, ruleset,"
    " ruleset_hash, seeds, opens_at, results_version, created_at) VALUES (1, 'old cup',"
    " 'time_trial', 'beginner_loop', 'ccw', 'total', '{}', :h, '[0]', CURRENT_TIMESTAMP, 0,"
    " CURRENT_TIMESTAMP)"
)
ENTRY = (
    "INSERT INTO entries (id, event_id, model_id, racer_id, created_at)"
    " VALUES (1, 1, 1, 1, CURRENT_TIMESTAMP)"
)
OLD_ROWS = (
    "INSERT INTO racers (id, alias, role, token_hash, created_at)"
    " VALUES (1, 'old', 'racer', :h, CURRENT_TIMESTAMP)",
    "INSERT INTO models (id, owner_id, name, sha256, size, info, created_at)"
    " VALUES (1, 1, 'm', :h, 10, '{}', CURRENT_TIMESTAMP)",
    EVENT,
    ENTRY,
    "INSERT INTO jobs (id, kind, event_id, entry_id, seed, status, attempts, max_attempts,"
    " created_at, updated_at) VALUES (1, 'evaluation', 1, 1, 0, 'queued', 0, 3,"
    " CURRENT_TIMESTAMP, CURRENT_TIMESTAMP)",
)


@pytest.fixture(scope="module")
def evals_league(database, tmp_path_factory: pytest.TempPathFactory):
    """A league where a racer may have 3 evaluation jobs waiting or running."""
    folder = tmp_path_factory.mktemp("evaluations") / "data"
    yield from start_league(database, folder, max_queued_jobs_per_racer=3)


@pytest.fixture(scope="module")
def bobs_model(evals_league: League) -> int:
    """A model of bob's that no evaluation is accepted for."""
    return upload(evals_league, "bob", seed=24)["id"]


def _evaluations(league: League, who: str, model_id: int) -> list[dict]:
    with league.client(who) as client:
        response = client.get(f"/api/models/{model_id}/evaluations")
    assert response.status_code == 200, response.text
    return response.json()


def test_a_worker_races_an_evaluation_on_another_track_and_its_laps_are_listed(
    evals_league: League,
) -> None:
    league = evals_league
    model = upload(league, "alice", seed=21, name="Zippy")["id"]
    body = {"track": TRACK, "direction": DIRECTION, "laps": 1}
    with league.client("alice") as client:
        response = client.post(f"/api/models/{model}/evaluations", json=body)
    assert response.status_code == 201, response.text
    created = response.json()
    assert (created["track"], created["direction"], created["race_type"]) == (
        TRACK,
        DIRECTION,
        "time_trial",
    )
    (job,) = created["jobs"]
    assert (job["status"], job["seed"], job["entry_id"]) == ("queued", 0, created["entry_id"])
    (waiting,) = _evaluations(league, "alice", model)
    assert waiting["status"] == "queued" and waiting["races"] == []
    assert waiting["name"] == "Evaluation: Zippy on Hairpin Hollow (cw)"

    worker = Worker(league.settings, "evaluator")
    try:
        while worker.run_once():
            pass
    finally:
        worker.close()

    (done,) = _evaluations(league, "alice", model)
    assert (done["event_id"], done["status"], done["error"]) == (created["event_id"], "done", None)
    (race,) = done["races"]
    assert race["status"] in ("finished", "dnf", "time_up")
    assert race["laps"] == len(race["lap_times_ms"]) <= 1
    assert {"best_lap_ms", "total_ms", "off_track", "crashes", "resets"} <= race.keys()
    with league.client() as anyone:  # the race and its replay work for anyone with the link
        shown = anyone.get(f"/api/races/{race['race_id']}").json()
        trace = anyone.get(f"/api/races/{race['race_id']}/trace")
        listed = [r["id"] for r in anyone.get("/api/races").json()]
        by_event = anyone.get("/api/races", params={"event": created["event_id"]}).json()
    assert race["race_id"] not in listed  # unlisted, as its event is
    assert [r["id"] for r in by_event] == [race["race_id"]]
    assert (shown["config"]["track"], shown["config"]["direction"]) == (TRACK, DIRECTION)
    assert shown["config"]["laps"] == 1
    assert trace.status_code == 200 and f"entry{created['entry_id']}" in trace.json()["trace"]


def test_an_evaluation_is_unlisted_private_and_takes_no_entries(evals_league: League) -> None:
    league = evals_league
    model = upload(league, "alice", seed=22, name="Quiet")["id"]
    other = upload(league, "bob", seed=23)["id"]
    body = {"track": "slipstream_speedway", "race_type": "head_to_bot", "laps": 2}
    bots = {"bots": 2, "bot_speed": 1.2}  # the race type's own settings, as training takes them
    with league.client("alice") as alice:
        created = alice.post(
            f"/api/models/{model}/evaluations", json={**body, "race_settings": bots}
        ).json()
        mine = alice.post(f"/api/events/{created['event_id']}/entries", json={"model_id": model})
    event_id = created["event_id"]
    assert created["direction"] == "ccw"  # the track file's own direction
    assert mine.status_code == 409 and "takes no entries" in mine.json()["detail"]
    listed = create_event(league, name="Open Cup")["id"]
    with league.client("bob") as bob:
        assert bob.get(f"/api/models/{model}/evaluations").status_code == 404
        stolen = bob.post(f"/api/models/{model}/evaluations", json=body)
        entered = bob.post(f"/api/events/{event_id}/entries", json={"model_id": other})
        events = [e["id"] for e in bob.get("/api/events").json()]
        home = read_page(bob.get("/").text)
    assert stolen.status_code == 404
    assert entered.status_code == 409
    assert listed in events and event_id not in events
    assert "Open Cup" in home.text and "Evaluation" not in home.text
    with league.client() as anyone:  # an evaluated model is not made public
        assert anyone.get(f"/api/models/{model}").status_code == 404
    admin_view = _evaluations(league, "admin", model)
    assert [e["event_id"] for e in admin_view] == [event_id]
    assert admin_view[0]["race_type"] == "head_to_bot" and admin_view[0]["laps"] == 2
    with league.sessions() as session:  # closed, it leaves no standings snapshot
        close_events(session, utcnow() + timedelta(days=2))
        event = session.scalar(select(Event).where(Event.id == event_id))
        assert event is not None and event.kind == "evaluation" and event.finalized_at is None
        assert (event.ruleset["bots"]["count"], event.ruleset["bots"]["speed"]) == (2, 1.2)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ({"track": "atlantis"}, "unknown track 'atlantis'"),
        ({"track": TRACK, "direction": "up"}, "direction"),
        ({"track": TRACK, "race_type": "head_to_model"}, "race_type"),
        ({"track": TRACK, "laps": 6}, "laps"),
        ({"track": TRACK, "races": 4}, "races"),
        ({"track": TRACK, "race_settings": {"bots": 2}}, "bots: only head_to_bot races"),
        (
            {"track": TRACK, "race_type": "head_to_bot", "race_settings": {"bots": 9}},
            "bots: Input should be less than or equal to 6",
        ),
        ({"track": TRACK, "race_settings": {"laps": 9}}, "laps: not a race-type setting"),
    ],
)
def test_a_bad_evaluation_is_refused_and_leaves_nothing(
    evals_league: League, bobs_model: int, body: dict, message: str
) -> None:
    with evals_league.client("bob") as client:
        response = client.post(f"/api/models/{bobs_model}/evaluations", json=body)
    assert response.status_code == 422 and message in response.json()["detail"]
    assert _evaluations(evals_league, "bob", bobs_model) == []


def test_evaluations_count_against_the_racers_queue_cap(evals_league: League) -> None:
    league = evals_league
    model = upload(league, "admin", seed=25)["id"]
    with league.client("admin") as client:
        first = client.post(f"/api/models/{model}/evaluations", json={"track": TRACK, "races": 3})
        second = client.post(f"/api/models/{model}/evaluations", json={"track": TRACK})
    assert first.status_code == 201 and len(first.json()["jobs"]) == 3
    assert second.status_code == 429 and second.headers["Retry-After"]
    assert "one racer may have 3" in second.json()["detail"]
    assert [e["event_id"] for e in _evaluations(league, "admin", model)] == [
        first.json()["event_id"]
    ]


@pytest.mark.parametrize(
    ("jobs", "status"),
    [
        (["queued", "queued"], "queued"),
        (["done", "queued"], "running"),
        (["running", "queued"], "running"),
        (["done", "failed", "done"], "failed"),
        (["done", "done"], "done"),
    ],
)
def test_an_evaluation_is_done_once_every_race_settled(jobs: list[str], status: str) -> None:
    assert evaluation_status(jobs) == status


def test_the_migration_keeps_events_entries_and_jobs_as_league_ones(
    database: Database, tmp_path: Path
) -> None:
    fresh = (
        _postgres_database()
        if database.backend == "postgres"
        else Database(f"sqlite:///{tmp_path / 'old.db'}", "sqlite")
    )
    engine = make_engine(fresh.url)
    try:
        upgrade(engine, "0006")
        with engine.begin() as conn:
            for statement in OLD_ROWS:
                conn.execute(text(statement), {"h": "0" * 64})
        upgrade(engine)
        with engine.begin() as conn:
            assert conn.execute(text("SELECT id, kind FROM events")).all() == [(1, "league")]
            assert conn.execute(text("SELECT count(*) FROM jobs")).scalar_one() == 1
            conn.execute(text(EVENT.replace("(1, 'old cup'", "(2, 'mine'")), {"h": "0" * 64})
            conn.execute(text("UPDATE events SET kind = 'evaluation' WHERE id = 2"))
            conn.execute(text(ENTRY.replace("(1, 1,", "(2, 2,")))
        with pytest.raises(IntegrityError), engine.begin() as conn:
            conn.execute(text("UPDATE events SET kind = 'secret' WHERE id = 1"))
        with engine.connect() as conn:  # 0008: an older event keeps the bot it raced
            assert conn.execute(text("SELECT round_bot FROM events WHERE id = 1")).scalar() == (
                "pursuit"
            )
        with pytest.raises(IntegrityError), engine.begin() as conn:
            conn.execute(text("UPDATE events SET round_bot = 'ghost' WHERE id = 1"))
        with engine.begin() as conn:  # an older league must not list an evaluation as its own
            command.downgrade(alembic_config(conn), "0006")
        with engine.connect() as conn:
            assert conn.execute(text("SELECT id FROM events")).scalars().all() == [1]
            assert conn.execute(text("SELECT id FROM entries")).scalars().all() == [1]
    finally:
        engine.dispose()
        fresh.drop()
