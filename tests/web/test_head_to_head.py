"""The head-to-head record of an event's real races: the JSON route and the event page."""

from __future__ import annotations

from typing import Any

from tests.league.conftest import League
from tests.web.data import Site


def expected_record(races: list[dict[str, Any]], me: int, other: int) -> dict[str, int]:
    """The record of model ``me`` against ``other``, counted from the races' car results."""
    record = {"races": 0, "wins": 0, "losses": 0, "overtakes": 0, "overtaken": 0}
    for race in races:
        cars = {c["model_id"]: c for c in race["cars"]}
        if me not in cars or other not in cars:
            continue
        record["races"] += 1
        record["wins"] += cars[me]["finish_position"] < cars[other]["finish_position"]
        record["losses"] += cars[other]["finish_position"] < cars[me]["finish_position"]
        if len(race["cars"]) == 2:
            record["overtakes"] += cars[me]["overtakes"]
            record["overtaken"] += cars[other]["overtakes"]
    return record


def test_head_to_head_route_counts_the_pairings_races(league: League, site: Site) -> None:
    with league.client() as client:
        (pairing,) = client.get(f"/api/events/{site.head_to_head}/head-to-head").json()
        races = client.get(f"/api/races?event={site.head_to_head}").json()
        assert client.get("/api/events/999999/head-to-head").status_code == 404
        assert client.get(f"/api/events/{site.time_trial}/head-to-head").json() == []
    me, other = pairing["model_id"], pairing["opponent_id"]
    assert {me, other} == {site.models["alice"], site.models["bob"]}
    assert pairing["alias"] == ("alice" if me == site.models["alice"] else "bob")
    shown = {k: pairing[k] for k in ("races", "wins", "losses", "overtakes", "overtaken")}
    assert shown == expected_record(races, me, other)
    assert shown["races"] == 2 == shown["wins"] + shown["losses"]


def test_event_page_shows_the_head_to_head_table(page, league: League, site: Site) -> None:
    with league.client() as client:
        (pairing,) = client.get(f"/api/events/{site.head_to_head}/head-to-head").json()
        assert 'id="head-to-head"' not in client.get(f"/events/{site.time_trial}").text
    page.goto(f"/events/{site.head_to_head}")
    row = page.locator(
        f'#head-to-head tr[data-model-id="{pairing["model_id"]}"]'
        f'[data-opponent-id="{pairing["opponent_id"]}"]'
    )
    cells = row.locator("td").all_text_contents()
    assert cells[0] == f"{pairing['alias']} · {pairing['model_name']}"
    assert cells[1:3] == [str(pairing["wins"]), str(pairing["losses"])]
    assert cells[3] == f"{pairing['opponent_alias']} · {pairing['opponent_name']}"
    assert cells[4:] == [str(pairing["races"]), f"{pairing['overtakes']} / {pairing['overtaken']}"]
