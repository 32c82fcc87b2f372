"""Honest head-to-head ratings, stored: finish ranks decide (not the order cars are listed),
and a race repeating an earlier one's (lineup, ruleset, seed) is not rated again."""

from __future__ import annotations

import logging
from dataclasses import replace

import pytest
from sqlalchemy import select

from arena.config import RaceConfig
from league.models import Event, Rating
from league.ranking import Skill
from tests.league.conftest import League
from tests.league.helpers import (
    car,
    create_event,
    enter,
    race_result,
    record,
    record_as_worker,
    upload,
)


def ratings(league: League, event_id: int) -> dict[int, Skill]:
    """The event's stored ratings by model id."""
    with league.sessions() as session:
        rows = session.scalars(select(Rating).where(Rating.event_id == event_id))
        return {r.model_id: Skill(r.mu, r.sigma, r.races) for r in rows}


def duel(league: League, name: str, seeds: tuple[int, ...]) -> tuple[int, list[tuple[int, int]]]:
    """A head-to-model event with one model each of admin, alice, bob; (event id,
    [(entry id, model id)])."""
    event = create_event(league, name=name, race_type="head_to_model", round_interval_s=600)
    entered = []
    for who, seed in zip(("admin", "alice", "bob"), seeds, strict=True):
        model = upload(league, who, seed)
        entered.append((enter(league, who, event["id"], model["id"])["entry_id"], model["id"]))
    return event["id"], entered


def test_the_winner_listed_last_or_in_the_middle_gets_the_higher_rating(league: League) -> None:
    event_id, [(e1, m1), (e2, m2), (e3, m3)] = duel(league, "Listed last", (71, 72, 73))
    slow = [12.0, 12.0, 12.0]
    # Cars are stored (and handed to the rating update) in grid order: the winner last.
    record(league, event_id, {e1: car("a", laps=slow, finish_position=2), e2: car("b")}, seed=1)
    after_one = ratings(league, event_id)
    assert after_one[m2].mu > after_one[m1].mu
    # Three cars, the winner in the middle, the runner-up first.
    cars = {
        e1: car("a", laps=[11.0, 11.0, 11.0], finish_position=2),
        e3: car("c", finish_position=1),
        e2: car("b", laps=slow, finish_position=3),
    }
    record(league, event_id, cars, seed=2)
    after_two = ratings(league, event_id)
    assert after_two[m3].mu > after_two[m1].mu > after_one[m1].mu
    assert after_two[m2].mu < after_one[m2].mu  # last this time: it loses rating


def test_a_repeated_race_is_not_rated_again(
    league: League, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="slipstream.ranking")
    event_id, [(e1, m1), (e2, m2), (e3, m3)] = duel(league, "Copies", (74, 75, 76))
    slow = [12.0, 12.0, 12.0]
    record(league, event_id, {e1: car("a"), e2: car("b", laps=slow, finish_position=2)}, seed=9)
    first = ratings(league, event_id)
    assert first[m1].races == first[m2].races == 1
    # The same lineup (on the other grid order) under the same ruleset and seed: a copy.
    record(league, event_id, {e2: car("b"), e1: car("a", laps=slow, finish_position=2)}, seed=9)
    assert ratings(league, event_id) == first
    assert "not rated" in caplog.text and f"[{min(m1, m2)}, {max(m1, m2)}]" in caplog.text
    # A fresh seed, or another lineup on the same seed, adds information.
    record(league, event_id, {e1: car("a"), e2: car("b", laps=slow, finish_position=2)}, seed=10)
    second = ratings(league, event_id)
    assert second[m1].races == 2 and second[m1].mu > first[m1].mu
    cars = {e1: car("a"), e2: car("b", laps=slow, finish_position=3)}
    cars[e3] = car("c", laps=[11.0, 11.0, 11.0], finish_position=2)
    record(league, event_id, cars, seed=9)
    third = ratings(league, event_id)
    assert third[m1].races == 3 and third[m3].races == 1


def test_the_same_lineup_and_seed_under_other_rules_is_rated_again(
    league: League, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="slipstream.ranking")
    event_id, [(e1, m1), (e2, m2), _] = duel(league, "Rules moved on", (77, 78, 79))
    cars = {e1: car("a"), e2: car("b", laps=[12.0, 12.0, 12.0], finish_position=2)}
    record(league, event_id, cars, seed=4)
    first = ratings(league, event_id)
    # A worker whose rules differ (here a longer time limit, as when an upgrade changes a
    # rule's default) races the same lineup on the same seed: another race, not a copy.
    with league.sessions() as session:
        result = race_result(session.get_one(Event, event_id), list(cars.values()), seed=4)
    rules = {**result.config.ruleset(), "time_limit_s": result.config.time_limit_s + 60.0}
    config = RaceConfig.build(**rules, cars=result.config.cars, seed=4)
    assert config.ruleset_hash() != result.config.ruleset_hash()
    record_as_worker(league, event_id, replace(result, config=config), {"a": e1, "b": e2})
    second = ratings(league, event_id)
    assert second[m1].races == second[m2].races == 2
    assert second[m1].mu > first[m1].mu and second[m2].mu < first[m2].mu
    assert "not rated" not in caplog.text
