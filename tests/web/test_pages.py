"""The pages and their JSON helpers over HTTP, without a browser."""

from __future__ import annotations

from pathlib import Path

from tests.league.conftest import League
from tests.web.data import METRICS_CSV, Site, model_with_metrics


def test_home_lists_events_with_thumbnails_racers_and_status(league: League, site: Site) -> None:
    with league.client() as client:
        html = client.get("/").text
    assert "Autumn Time Trial" in html and "Head-to-Head Cup" in html
    assert html.count("<svg") >= 2
    assert f'href="/events/{site.time_trial}"' in html
    assert "3 racers" in html and "2 racers" in html
    assert "time trial" in html and "head to model" in html


def test_event_race_model_and_upload_pages_render(league: League, site: Site) -> None:
    with league.client() as client:
        for path in (
            f"/events/{site.time_trial}",
            f"/races/{site.races['alice']}",
            f"/models/{site.models['alice']}",
            "/upload",
            "/static/replay.js",
            "/static/style.css",
        ):
            response = client.get(path)
            assert response.status_code == 200, path
        assert client.get("/races/999999").status_code == 404
        assert client.get("/events/999999").status_code == 404


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
