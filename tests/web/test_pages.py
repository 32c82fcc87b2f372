"""The pages and their JSON helpers over HTTP, without a browser."""

from __future__ import annotations

import re
from pathlib import Path

from tests.league.conftest import League
from tests.league.page_text import read_page
from tests.web.data import METRICS_CSV, Site, model_with_metrics


def test_home_lists_events_with_thumbnails_racers_and_status(league: League, site: Site) -> None:
    with league.client() as client:
        html = client.get("/").text
    page = read_page(html)
    assert {"Autumn Time Trial", "Head-to-Head Cup"} <= set(page.headings)
    assert html.count("<svg") >= 2
    assert f'href="/events/{site.time_trial}"' in html
    assert "3 racers" in page.text and "2 racers" in page.text
    assert "time trial" in page.text and "head to model" in page.text


def test_event_page_names_the_event_and_its_rules(league: League, site: Site) -> None:
    with league.client() as client:
        trial = read_page(client.get(f"/events/{site.time_trial}").text)
        duel = read_page(client.get(f"/events/{site.head_to_head}").text)
        missing = client.get("/events/999999")
    assert trial.headings[0] == "Autumn Time Trial" and "Autumn Time Trial" in trial.title
    for words in ("open", "time trial", "beginner loop", "ranked by total time", "Latest races"):
        assert words in trial.text, words
    assert re.search(r"\b1 lap\b", trial.text)
    assert "Head to head" not in trial.headings
    assert duel.headings[:2] == ["Head-to-Head Cup", "Head to head"]
    assert "head to model" in duel.text and "ranked by rating" in duel.text
    assert "A model entered alone races the racer bot." in duel.text
    assert "entered alone" not in trial.text
    (row,) = duel.tables["head-to-head"]
    assert (row[0], row[3], row[4]) == ("alice · alice-model", "bob · bob-model", "2")
    assert int(row[1]) + int(row[2]) == 2  # each race: one model ahead of the other
    assert missing.status_code == 404 and missing.json()["detail"] == "Event 999999 not found."


def test_leaderboard_lists_each_racers_counting_race_and_time(league: League, site: Site) -> None:
    with league.client() as client:
        rows = client.get(f"/api/events/{site.time_trial}/leaderboard").json()["rows"]
        races = {
            who: client.get(f"/api/races/{site.races[who]}").json() for who in ("alice", "bob")
        }
    shown = {row["alias"]: row for row in rows}
    for who, race in races.items():
        (result,) = race["cars"]
        assert result["alias"] == who and shown[who]["race_id"] == race["id"]
        assert shown[who]["total_time_ms"] == result["total_ms"] is not None
        assert shown[who]["best_lap_ms"] == result["best_ms"]
    times = [row["total_time_ms"] for row in rows if row["total_time_ms"] is not None]
    assert [row["rank"] for row in rows] == list(range(1, len(rows) + 1))
    assert times == sorted(times) and shown["alice"]["rank"] < shown["bob"]["rank"]


def test_replay_page_names_its_race_and_its_cars(league: League, site: Site) -> None:
    race_id = site.races["h2h1"]
    with league.client() as client:
        page = read_page(client.get(f"/races/{race_id}").text)
        race = client.get(f"/api/races/{race_id}").json()
        missing = client.get("/races/999999")
    assert page.title.startswith(f"Race {race_id}")
    assert f"Head-to-Head Cup › race {race_id} (seed 1)" in page.text
    assert "Cars" in page.headings
    cars = sorted((c["alias"], c["car_name"], c["finish_position"]) for c in race["cars"])
    assert [car[:2] for car in cars] == [("alice", "alice"), ("bob", "bob")]
    assert sorted(car[2] for car in cars) == [1, 2]
    assert missing.status_code == 404 and missing.json()["detail"] == "Race 999999 not found."


def test_model_and_upload_pages_say_what_they_are(league: League, site: Site) -> None:
    model_id = site.models["alice"]
    with league.client() as client:
        model = read_page(client.get(f"/models/{model_id}").text)
        upload = read_page(client.get("/upload").text)
        script, style = client.get("/static/replay.js"), client.get("/static/style.css")
    assert model.headings[:2] == [f"Model {model_id}", "Validation report"]
    assert "Results" in model.headings
    assert upload.headings[0] == "Upload a model" and "Your models" in upload.headings
    assert "Model file" in upload.text and "Name (optional)" in upload.text
    assert script.status_code == style.status_code == 200
    assert "javascript" in script.headers["content-type"]
    assert style.headers["content-type"].startswith("text/css")


def test_pages_stay_out_of_the_api_schema(league: League, site: Site) -> None:
    with league.client() as client:
        paths = client.get("/openapi.json").json()["paths"]
    assert "/api/tracks/{name}" in paths
    assert not any(p.startswith(("/events", "/races", "/models", "/upload")) for p in paths)


def test_track_geometry_in_either_direction(league: League) -> None:
    with league.client() as client:
        ccw = client.get("/api/tracks/beginner_loop").json()
        cw = client.get("/api/tracks/beginner_loop", params={"direction": "cw"}).json()
        missing = client.get("/api/tracks/no_such_track")
    assert ccw["direction"] == "ccw" and cw["direction"] == "cw"
    assert len(ccw["left"]) == len(ccw["right"]) == len(ccw["waypoints"]) > 10
    assert ccw["waypoints"][0] == cw["waypoints"][-1]
    assert missing.status_code == 404 and "no_such_track" in missing.json()["detail"]


def test_model_history_is_for_its_owner(league: League, site: Site) -> None:
    path = f"/api/models/{site.models['alice']}/races"
    with league.client("alice") as alice, league.client("bob") as bob, league.client() as anon:
        races = alice.get(path).json()
        assert {r["race_id"] for r in races} == {
            site.races["alice"],
            site.races["h2h0"],
            site.races["h2h1"],
        }
        assert races[0]["event_name"] == "Head-to-Head Cup"
        assert bob.get(path).status_code == 404
        assert anon.get(path).status_code == 401


def test_metrics_come_from_the_archive(league: League, tmp_path: Path) -> None:
    archive = model_with_metrics(tmp_path)
    with league.client("bob") as bob, archive.open("rb") as handle:
        model = bob.post("/api/models", files={"file": (archive.name, handle)}).json()
        metrics = bob.get(f"/api/models/{model['id']}/metrics").json()
        plain = bob.get("/api/models").json()[-1]
        no_metrics = bob.get(f"/api/models/{plain['id']}/metrics")
    rows = METRICS_CSV.strip().splitlines()
    assert metrics["columns"] == rows[0].split(",")
    assert metrics["values"]["mean_reward"][:3] == [10.0, 14.0, 18.0]
    assert metrics["values"]["eval_progress"][:4] == [0.0, None, None, 27.0]
    assert no_metrics.status_code == 404
