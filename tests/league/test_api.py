"""The league API end to end against a real server: racers, uploads, events, entries,
jobs, leaderboards and races."""

from __future__ import annotations

import zipfile
from dataclasses import replace

from sqlalchemy import select

from league.models import Event, Job
from tests.league.conftest import UPLOAD_LIMIT, League
from tests.league.helpers import (
    car,
    create_event,
    enter,
    model_rows,
    race_result,
    record,
    record_as_worker,
    upload,
)


def test_health_and_readiness(league: League) -> None:
    with league.client() as client:
        assert client.get("/healthz").json() == {"status": "ok"}
        assert client.get("/readyz").json() == {"status": "ok"}
        assert "/api/events/{event_id}/leaderboard" in client.get("/openapi.json").json()["paths"]


def test_create_racer_shows_token_once_and_it_works(league: League) -> None:
    with league.client("admin") as admin:
        answer = admin.post("/api/racers", json={"alias": "carol"})
        assert answer.status_code == 201
        token = answer.json()["token"]
        assert admin.post("/api/racers", json={"alias": "carol"}).status_code == 409
    with league.client() as anon:
        me = anon.get("/api/racers/me", headers={"Authorization": f"Bearer {token}"})
    assert me.json()["alias"] == "carol" and "token" not in me.json()
    with league.sessions() as session:
        from league.models import Racer

        stored = session.scalar(select(Racer.token_hash).where(Racer.alias == "carol"))
    assert stored != token and len(stored) == 64


def test_upload_validates_and_deduplicates(league: League) -> None:
    first = upload(league, "alice", seed=1, name="first")
    assert first["visibility"] == "owner" and first["info"]["sensors"] == ["lidar"]
    again = upload(league, "alice", seed=1)
    assert again["id"] == first["id"]
    with league.client("alice") as client:
        mine = client.get("/api/models").json()
    assert [m["id"] for m in mine].count(first["id"]) == 1


def test_invalid_upload_lists_problems(league: League, tmp_path) -> None:
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as zf:
        zf.writestr("hello.txt", "not a model")
    before = model_rows(league)
    with league.client("alice") as client:
        response = client.post("/api/models", files={"file": ("bad.zip", bad.read_bytes())})
    assert response.status_code == 422
    body = response.json()
    assert "refused" in body["detail"] and body["problems"]
    assert {"field", "expected", "found", "message"} <= set(body["problems"][0])
    assert model_rows(league) == before


def test_too_large_upload_is_413(league: League) -> None:
    with league.client("alice") as client:
        big = b"\0" * (UPLOAD_LIMIT + 1)
        response = client.post("/api/models", files={"file": ("big.zip", big)})
        assert response.status_code == 413
        assert "limit" in response.json()["detail"]
        huge = b"\0" * (UPLOAD_LIMIT + 200_000)
        response = client.post("/api/models", files={"file": ("huge.zip", huge)})
        assert response.status_code == 413


def test_event_validation_is_readable(league: League) -> None:
    with league.client("admin") as admin:
        unknown = admin.post("/api/events", json={"name": "x", "track": "nowhere"})
        assert unknown.status_code == 422 and "nowhere" in unknown.json()["detail"]
        boxes = admin.post("/api/events", json={"name": "x", "race_type": "object_avoidance"})
        assert boxes.status_code == 422 and "obstacles" in boxes.json()["detail"]
        times = {"opens_at": "2030-01-02T00:00:00Z", "closes_at": "2030-01-01T00:00:00"}
        window = admin.post("/api/events", json={"name": "x", **times})
        assert window.status_code == 422
        lone = admin.post("/api/events", json={"name": "x", "round_bot": "racer"})
        assert lone.status_code == 422 and "head_to_model" in lone.json()["detail"]
        ghost = {"name": "x", "race_type": "head_to_model", "round_bot": "ghost"}
        unknown_bot = admin.post("/api/events", json=ghost)
        assert unknown_bot.status_code == 422 and "racer" in str(unknown_bot.json()["detail"])


def test_a_head_to_model_event_says_which_bot_fills_its_grids(league: League) -> None:
    cup = create_event(league, name="Cup", race_type="head_to_model", round_interval_s=60)
    assert cup["round_bot"] == "racer"  # the default
    slow = create_event(league, name="Slow", race_type="head_to_model", round_bot="pursuit")
    with league.client() as anon:
        assert anon.get(f"/api/events/{slow['id']}").json()["round_bot"] == "pursuit"


def test_time_trial_flow_and_leaderboard(league: League) -> None:
    event = create_event(league, name="Sprint", ranking_metric="total", seeds=[7, 8])
    assert event["status"] == "open" and event["ruleset"]["laps"] == 3
    a1 = upload(league, "alice", seed=11)
    a2 = upload(league, "alice", seed=12)
    b1 = upload(league, "bob", seed=13)
    entry_a1 = enter(league, "alice", event["id"], a1["id"])
    entry_a2 = enter(league, "alice", event["id"], a2["id"])
    entry_b1 = enter(league, "bob", event["id"], b1["id"])
    assert len(entry_a1["job_ids"]) == 2
    with league.client("alice") as client:
        job = client.get(f"/api/jobs/{entry_a1['job_ids'][0]}").json()
        assert job["status"] == "queued" and job["seed"] == 7
        twice = client.post(f"/api/events/{event['id']}/entries", json={"model_id": a1["id"]})
        assert twice.status_code == 409
    # alice: a slow finish and a faster one; bob: faster still but with an off-track penalty
    record(league, event["id"], {entry_a1["entry_id"]: car("a1", laps=[11, 11, 11])}, seed=7)
    race_id = record(league, event["id"], {entry_a2["entry_id"]: car("a2", laps=[10, 10, 10])}, 7)
    record(
        league,
        event["id"],
        {entry_b1["entry_id"]: car("b1", laps=[9, 9.5, 9], off_track_count=2)},
        seed=7,
    )
    with league.client() as anon:
        board = anon.get(f"/api/events/{event['id']}/leaderboard").json()
        rows = board["rows"]
        assert [(r["rank"], r["alias"]) for r in rows] == [(1, "bob"), (2, "alice")]
        assert rows[0]["ranking_score_ms"] == 27500 and rows[0]["off_track_count"] == 2
        assert rows[1]["total_time_ms"] == 30000 and rows[1]["submission_count"] == 2
        assert rows[1]["model_id"] == a2["id"] and rows[1]["mu"] is None
        race = anon.get(f"/api/races/{race_id}").json()
        assert race["cars"][0]["lap_times_ms"] == [10000, 10000, 10000]
        assert race["cars"][0]["alias"] == "alice" and race["config"]["seed"] == 7
        trace = anon.get(f"/api/races/{race_id}/trace").json()
        assert trace["trace"]["a2"]["x"] == [0.0, 0.1]
        listed = anon.get("/api/races", params={"event": event["id"]}).json()
        assert len(listed) == 3 and all(r["event_id"] == event["id"] for r in listed)
        public = anon.get(f"/api/models/{b1['id']}").json()
        assert public["visibility"] == "public" and public["info"] is None
    with league.client("alice") as client:
        assert client.get(f"/api/jobs/{entry_a2['job_ids'][0]}").json()["race_id"] == race_id


def test_dnf_ranks_after_finishers(league: League) -> None:
    event = create_event(league, name="Best lap", ranking_metric="best", seeds=[0])
    a = upload(league, "alice", seed=21)
    b = upload(league, "bob", seed=22)
    ea = enter(league, "alice", event["id"], a["id"])
    eb = enter(league, "bob", event["id"], b["id"])
    record(league, event["id"], {ea["entry_id"]: car("a", status="dnf", laps=[5.0])})
    record(league, event["id"], {eb["entry_id"]: car("b", laps=[12, 12, 12])})
    with league.client() as anon:
        rows = anon.get(f"/api/events/{event['id']}/leaderboard").json()["rows"]
    assert [r["alias"] for r in rows] == ["bob", "alice"]
    assert rows[1]["ranking_score_ms"] is None and rows[1]["status"] == "dnf"


def test_head_to_model_ratings(league: League) -> None:
    event = create_event(league, name="Duel", race_type="head_to_model", round_interval_s=600)
    a = upload(league, "alice", seed=31)
    b = upload(league, "bob", seed=32)
    ea = enter(league, "alice", event["id"], a["id"])
    eb = enter(league, "bob", event["id"], b["id"])
    assert ea["job_ids"] == [] and eb["job_ids"] == []
    with league.client() as anon:
        rows = anon.get(f"/api/events/{event['id']}/leaderboard").json()["rows"]
        assert {r["alias"] for r in rows} == {"alice", "bob"} and rows[0]["mu"] is None
    for seed in range(3):
        record(
            league,
            event["id"],
            {
                ea["entry_id"]: car("a", finish_position=1),
                eb["entry_id"]: car("b", laps=[12, 12, 12], finish_position=2),
            },
            seed=seed,
        )
    with league.client() as anon:
        rows = anon.get(f"/api/events/{event['id']}/leaderboard").json()["rows"]
    assert rows[0]["alias"] == "alice" and rows[0]["mu"] > rows[1]["mu"]
    assert rows[0]["ordinal"] == rows[0]["mu"] - 3 * rows[0]["sigma"]


def test_closed_event_refuses_entries(league: League) -> None:
    event = create_event(
        league, name="Past", opens_at="2020-01-01T00:00:00Z", closes_at="2020-02-01T00:00:00Z"
    )
    assert event["status"] == "closed"
    model = upload(league, "alice", seed=41)
    with league.client("alice") as client:
        answer = client.post(f"/api/events/{event['id']}/entries", json={"model_id": model["id"]})
    assert answer.status_code == 409 and "not open" in answer.json()["detail"]
    with league.sessions() as session:
        assert session.scalars(select(Job).where(Job.event_id == event["id"])).all() == []


def test_racing_metrics_reach_the_race_the_leaderboard_and_the_replay(league: League) -> None:
    event = create_event(league, name="Pass Masters", race_type="head_to_model", seeds=[0])
    a = upload(league, "alice", seed=41)
    b = upload(league, "bob", seed=42)
    ea = enter(league, "alice", event["id"], a["id"])["entry_id"]
    eb = enter(league, "bob", event["id"], b["id"])["entry_id"]
    winner = car("a", finish_position=1, overtakes=2, laps_led=3, gap_to_winner=0.0)
    loser = car(
        "b",
        laps=[12, 12, 12],
        finish_position=2,
        times_overtaken=2,
        at_fault_collisions=1,
        gap_to_winner=7.2,
    )
    events = [
        {"t": 4.0, "kind": "contact", "car": "b", "other": "a", "at_fault": True},
        {"t": 9.5, "kind": "overtake", "car": "a", "other": "b", "at_fault": False},
    ]
    with league.sessions() as session:
        result = race_result(session.get_one(Event, event["id"]), [winner, loser])
    race_id = record_as_worker(
        league, event["id"], replace(result, events=events), {"a": ea, "b": eb}
    )
    with league.client() as anon:
        cars = {c["car_name"]: c for c in anon.get(f"/api/races/{race_id}").json()["cars"]}
        rows = anon.get(f"/api/events/{event['id']}/leaderboard").json()["rows"]
        trace = anon.get(f"/api/races/{race_id}/trace").json()
    alice = cars["a"]
    assert (alice["overtakes"], alice["laps_led"], alice["gap_to_winner_ms"]) == (2, 3, 0)
    assert (cars["b"]["times_overtaken"], cars["b"]["at_fault_collisions"]) == (2, 1)
    assert cars["b"]["gap_to_winner_ms"] == 7200
    by_alias = {r["alias"]: r for r in rows}
    assert by_alias["alice"]["overtakes"] == 2 and by_alias["alice"]["laps_led"] == 3
    assert by_alias["bob"]["at_fault_collisions"] == 1
    assert by_alias["bob"]["gap_to_winner_ms"] == 7200
    assert trace["events"] == events
