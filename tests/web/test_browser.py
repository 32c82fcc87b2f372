"""The pages in real headless Chromium: leaderboard, replay, model page and upload form."""

from __future__ import annotations

import re
from pathlib import Path

from league.models import Entry, Event, utcnow
from tests.league.conftest import League
from tests.league.helpers import create_event, enter, upload
from tests.web.data import Site, duel, race, record

TOKEN_KEY = "slipstream.token"


def sign_in(page, league: League, who: str) -> None:
    """Store ``who``'s token the way the header form does, before any page script runs."""
    token = league.tokens[who]
    page.add_init_script(f"window.localStorage.setItem({TOKEN_KEY!r}, {token!r});")


def save_screenshot(page, path: Path) -> None:
    """The page down to the end of its content (the viewport's width)."""
    box = page.locator("main").bounding_box()
    width = page.viewport_size["width"]
    page.screenshot(
        path=str(path), clip={"x": 0, "y": 0, "width": width, "height": box["y"] + box["height"]}
    )


def board_rows(page) -> list[list[str]]:
    return page.eval_on_selector_all(
        "#leaderboard tbody tr[data-model-id]",
        "rows => rows.map(r => Array.from(r.cells, c => c.textContent.trim()))",
    )


def test_leaderboard_renders_the_api_rows_and_updates_itself(
    page, league: League, site: Site, screenshot_dir: Path | None
) -> None:
    page.goto(f"/events/{site.time_trial}")
    page.wait_for_selector("#leaderboard[data-loaded=true] tbody tr[data-model-id]")
    with league.client() as client:
        api_rows = client.get(f"/api/events/{site.time_trial}/leaderboard").json()["rows"]
    shown = board_rows(page)
    assert [r[1] for r in shown] == [r["alias"] for r in api_rows] == ["alice", "bob"]
    headers = page.eval_on_selector_all("#leaderboard th", "cells => cells.map(c => c.textContent)")
    assert headers[:4] == ["Rank", "Racer", "Model", "Time"] and "Off-track" in headers
    best = api_rows[1]["best_lap_ms"]
    assert shown[1][4] == f"0:{best / 1000:06.3f}"
    assert shown[1][headers.index("Off-track")] == str(api_rows[1]["off_track_count"]) != "0"

    with league.sessions() as session:
        from league.models import Event

        event = session.get(Event, site.time_trial)
        session.expunge(event)
    record(
        league,
        site.time_trial,
        race(event, {"carol": (0.4, None)}, 0),
        {"carol": site.entries["carol"]},
    )
    page.wait_for_function(
        "() => Array.from(document.querySelectorAll('#leaderboard tbody tr'))"
        ".some(r => r.cells[1] && r.cells[1].textContent === 'carol')",
        timeout=40_000,  # a hang guard: 10 times the page's 4 s poll (POLL_MS)
    )
    assert [r[1] for r in board_rows(page)] == ["alice", "bob", "carol"]
    if screenshot_dir is not None:
        save_screenshot(page, screenshot_dir / "leaderboard.png")


def test_head_to_head_board_shows_ratings_and_uncertainty(page, site: Site) -> None:
    page.goto(f"/events/{site.head_to_head}")
    page.wait_for_selector("#leaderboard tbody tr[data-model-id] .ubar .range")
    headers = page.eval_on_selector_all("#leaderboard th", "cells => cells.map(c => c.textContent)")
    assert headers[3:7] == ["μ", "σ", "μ − 3σ", "Uncertainty"]
    assert [r[1] for r in board_rows(page)] == ["alice", "bob"]


def test_replay_loads_the_trace_and_the_cars_move_when_played(
    page, site: Site, screenshot_dir: Path | None
) -> None:
    page.goto(f"/races/{site.races['h2h1']}")
    page.wait_for_selector("#replay[data-ready=true]")
    start = page.evaluate("window.slipReplay.positions()")
    assert set(start) == {"alice", "bob"}
    splits = page.eval_on_selector_all(
        ".car-card .splits tbody tr",
        "rows => rows.map(r => Array.from(r.cells, c => c.textContent))",
    )
    assert len(splits) == 2
    for row in splits:
        assert all(re.fullmatch(r"\d+\.\d{3}", cell) for cell in row[1:]), row
        assert abs(sum(float(c) for c in row[1:4]) - float(row[4])) < 0.002
    assert "off track at" in page.inner_text(".car-card[data-car=bob] .incidents")

    page.click("button[data-speed='4']")
    page.click("#play")
    page.wait_for_function("() => window.slipReplay.state().time > 2")
    page.click("#play")
    state = page.evaluate("window.slipReplay.state()")
    moved = page.evaluate("window.slipReplay.positions()")
    assert state["speed"] == 4 and not state["playing"]
    for car in ("alice", "bob"):
        assert abs(moved[car][0] - start[car][0]) + abs(moved[car][1] - start[car][1]) > 0.5

    page.eval_on_selector(
        "#scrub", "s => { s.value = '500'; s.dispatchEvent(new Event('input')); }"
    )
    state = page.evaluate("window.slipReplay.state()")
    assert abs(state["time"] - state["duration"] / 2) < 0.1
    if screenshot_dir is not None:
        save_screenshot(page, screenshot_dir / "replay.png")


def test_replay_marks_each_overtake_and_contact_with_the_car_at_fault(
    page, league: League, screenshot_dir: Path | None
) -> None:
    event_id = create_event(
        league,
        name="Overtaking Cup",
        race_type="head_to_model",
        track="slipstream_speedway",
        laps=2,
        seeds=[0],
        time_limit_s=90.0,
    )["id"]
    # fresh models, so that the other tests' models keep their race histories
    models = {
        who: upload(league, who, seed, name=f"{who}-racer")["id"]
        for who, seed in (("alice", 51), ("bob", 52))
    }
    entries = {who: enter(league, who, event_id, models[who])["entry_id"] for who in models}
    with league.sessions() as session:
        event = session.get_one(Event, event_id)
        session.expunge(event)
    result = duel(event, fast="alice", slow="bob")
    kinds = [e["kind"] for e in result.events]
    assert "overtake" in kinds and "contact" in kinds  # the race has both to show
    race_id = record(league, event_id, result, entries)

    page.goto(f"/races/{race_id}")
    page.wait_for_selector("#replay[data-ready=true]")
    listed = page.eval_on_selector_all(
        "#race-events li.race-event",
        "items => items.map(li => [li.dataset.kind, li.dataset.car, li.dataset.atFault,"
        " li.textContent])",
    )
    expected = [(e["kind"], e["car"], str(e["at_fault"]).lower()) for e in result.events]
    assert [tuple(item[:3]) for item in listed] == expected
    for (kind, car, at_fault, text), event in zip(listed, result.events, strict=True):
        if kind == "overtake":
            assert f"{car} passed {event['other']}" in text
        elif at_fault == "true":
            assert text.endswith(f"{car} at fault")
    passes = result.car("alice").overtakes
    assert passes >= 1
    assert f"overtakes {passes} " in page.inner_text(".car-card[data-car=alice] .racing")

    first = min(e["t"] for e in result.events)
    page.eval_on_selector(
        "#scrub",
        f"s => {{ s.value = '{int(1000 * first / result.duration) - 1}';"
        " s.dispatchEvent(new Event('input')); }",
    )
    assert page.evaluate("window.slipReplay.marks()") == []
    page.eval_on_selector(
        "#scrub", "s => { s.value = '1000'; s.dispatchEvent(new Event('input')); }"
    )
    marks = page.evaluate("window.slipReplay.marks()")
    assert [(m["kind"], m["car"], m["at_fault"]) for m in marks] == [
        (e["kind"], e["car"], e["at_fault"]) for e in result.events
    ]
    for mark in marks:
        blamed = mark["kind"] == "contact" and mark["at_fault"]
        assert mark["label"] == (f"{mark['car']} at fault" if blamed else None)
    if screenshot_dir is not None:
        save_screenshot(page, screenshot_dir / "replay-racing.png")

    page.goto(f"/events/{event_id}")
    page.wait_for_selector("#leaderboard[data-loaded=true] tbody tr[data-model-id]")
    headers = page.eval_on_selector_all("#leaderboard th", "cells => cells.map(c => c.textContent)")
    with league.client() as client:
        api_rows = client.get(f"/api/events/{event_id}/leaderboard").json()["rows"]
    shown = {row[1]: row for row in board_rows(page)}
    for row in api_rows:
        cells = shown[row["alias"]]
        assert cells[headers.index("Overtakes")] == str(row["overtakes"])
        assert cells[headers.index("At fault")] == str(row["at_fault_collisions"])
    alice = next(r for r in api_rows if r["alias"] == "alice")
    assert alice["overtakes"] == passes and alice["at_fault_collisions"] >= 1


def test_ghost_compares_a_best_lap_with_the_leader(page, site: Site) -> None:
    page.goto(f"/races/{site.races['bob']}")
    page.wait_for_selector("#replay[data-ready=true]")
    page.check("#ghost-on")
    page.wait_for_function(
        "() => document.getElementById('ghost-info').textContent.includes('vs leader')"
    )
    info = page.inner_text("#ghost-info")
    assert re.match(r"lap 0:\d\d\.\d{3} vs leader 0:\d\d\.\d{3}", info), info
    state = page.evaluate("window.slipReplay.state()")
    assert 10 < state["duration"] < 40


def test_upload_form_shows_the_validators_message(
    page, league: League, site: Site, tmp_path: Path
) -> None:
    bad = tmp_path / "broken.zip"
    bad.write_bytes(b"this is not a zip archive")
    with league.client("alice") as client:
        answer = client.post("/api/models", files={"file": (bad.name, bad.read_bytes())}).json()
    sign_in(page, league, "alice")
    page.goto("/upload")
    page.wait_for_selector("#my-models tbody tr")
    page.set_input_files("#upload-file", str(bad))
    page.click("#upload-form button[type=submit]")
    page.wait_for_selector("#upload-result.error li")
    text = page.inner_text("#upload-result")
    assert answer["detail"] in text
    assert answer["problems"][0]["message"] in text


def test_model_page_shows_report_history_and_reward_graph_to_its_owner(
    page, league: League, site: Site
) -> None:
    page.goto(f"/models/{site.models['alice']}")
    page.wait_for_function(
        "() => document.getElementById('model-note').textContent.includes('Public view')"
    )
    sign_in(page, league, "alice")
    page.goto(f"/models/{site.models['alice']}")
    page.wait_for_selector("#history tbody tr")
    assert "passed" in page.inner_text("#report")
    assert page.eval_on_selector_all("#history tbody tr", "rows => rows.length") >= 3
    assert "without training metrics" in page.inner_text("#metrics-note")


def test_model_page_tells_its_owner_which_events_suspended_it(page, league: League) -> None:
    model_id = upload(league, "bob", 21, name="bob-faulty")["id"]
    event = create_event(league, name="Suspension Cup")
    listed = create_event(league, name="Still Racing Cup")
    entry_id = enter(league, "bob", event["id"], model_id)["entry_id"]
    enter(league, "bob", listed["id"], model_id)
    message = f"Model {model_id} was suspended from event {event['id']}: 3 races lost to faults"
    with league.sessions() as session:  # as league.jobs.faults.suspend_faulty leaves it
        entry = session.get_one(Entry, entry_id)
        entry.suspended_at, entry.suspension = utcnow(), message
        session.commit()
    with league.client("bob") as client:
        (mine,) = [m for m in client.get("/api/models").json() if m["id"] == model_id]
    assert [s["event_name"] for s in mine["suspensions"]] == ["Suspension Cup"]
    with league.client() as anonymous:  # the public view does not show it
        assert anonymous.get(f"/api/models/{model_id}").json()["suspensions"] == []

    sign_in(page, league, "bob")
    page.goto(f"/models/{model_id}")
    page.wait_for_selector("#suspensions:not([hidden])")
    shown = page.inner_text("#suspensions")
    assert "Suspension Cup" in shown and message in shown
    assert "Still Racing Cup" not in shown
