"""Standings: rank per-car results by an event's metric, and rate head-to-head races.

Lap times from the arena already hold the penalties (a penalised car is frozen while the
clock runs), so the ranking score is the metric itself: total time of the race's laps,
best lap or average lap, in ms. Cars that finished rank before those that did not; those
rank by laps done, then distance. Each racer's best result counts. Head-to-head events rank
by the conservative openskill rating (``ordinal = mu - 3 sigma``), updated from finish
positions; a race repeating an earlier one's lineup, ruleset and seed is not rated again.

The pure functions (:func:`standings`, :func:`rate`) know nothing of the database;
:func:`leaderboard` and :func:`rate_race` read and write an event's stored results with
them, and :func:`standing_row` is the one JSON form of a leaderboard row.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from openskill.models import PlackettLuce
from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload

from league.crud import bump_results_version
from league.models import Entry, Event, Model, Race, RaceCar, Racer, Rating

log = logging.getLogger("slipstream.ranking")
METRIC_FIELD = {"total": "total_ms", "best": "best_ms", "average": "average_ms"}
_MODEL = PlackettLuce()


@dataclass(frozen=True)
class Result:
    """One car's result in one race, with who drove it and its racing metrics."""

    racer_id: int
    alias: str
    model_id: int
    model_name: str
    race_id: int | None
    status: str | None
    laps: int
    best_ms: int | None
    average_ms: int | None
    total_ms: int | None
    off_track_count: int
    crash_count: int
    reset_count: int
    distance_m: float
    overtakes: int = 0
    times_overtaken: int = 0
    at_fault_collisions: int = 0
    laps_led: int = 0
    gap_to_winner_ms: int | None = None


def unraced(racer_id: int, alias: str, model_id: int, model_name: str) -> Result:
    """A placeholder result for an entry that has not raced yet."""
    return Result(
        racer_id, alias, model_id, model_name, None, None, 0, None, None, None, 0, 0, 0, 0.0
    )


@dataclass(frozen=True)
class Skill:
    """An openskill rating."""

    mu: float
    sigma: float
    races: int = 0

    @property
    def ordinal(self) -> float:
        """The conservative rating: mu - 3 sigma."""
        return self.mu - 3.0 * self.sigma


@dataclass(frozen=True)
class Standing:
    """One leaderboard row: a racer's counting result."""

    rank: int
    result: Result
    score_ms: int | None
    submissions: int
    skill: Skill | None


def score(result: Result, metric: str) -> int | None:
    """The ranking score in ms, or None for a car that did not finish."""
    if result.status != "finished":
        return None
    return getattr(result, METRIC_FIELD[metric])


def result_key(result: Result, metric: str) -> tuple:
    """Sort key: finished first by score, then the rest by laps and distance (more first)."""
    value = score(result, metric)
    if value is not None:
        return (0, value, 0, 0.0, result.race_id or 0)
    return (1, 0, -result.laps, -result.distance_m, result.race_id or 0)


def _key(result: Result, metric: str, skills: dict[int, Skill] | None) -> tuple:
    if skills is None:
        return result_key(result, metric)
    skill = skills.get(result.model_id)
    rated = (0, -skill.ordinal) if skill is not None else (1, 0.0)
    return (*rated, *result_key(result, metric))


def standings(
    results: Iterable[Result],
    metric: str,
    submissions: dict[int, int],
    skills: dict[int, Skill] | None = None,
) -> list[Standing]:
    """Rank racers by their best result; with ``skills`` (head-to-head) by rating first.

    ``submissions`` maps racer id to models entered; ``skills`` maps model id to rating.
    Ties keep the earlier race ahead, then the alias decides.
    """
    best: dict[int, Result] = {}
    for result in results:
        held = best.get(result.racer_id)
        if held is None or _key(result, metric, skills) < _key(held, metric, skills):
            best[result.racer_id] = result
    ordered = sorted(best.values(), key=lambda r: (_key(r, metric, skills), r.alias))
    return [
        Standing(
            rank=i + 1,
            result=r,
            score_ms=score(r, metric),
            submissions=submissions.get(r.racer_id, 0),
            skill=skills.get(r.model_id) if skills is not None else None,
        )
        for i, r in enumerate(ordered)
    ]


def initial_skill() -> Skill:
    """A new model's rating (openskill defaults: mu 25, sigma 25/3)."""
    rating = _MODEL.rating()
    return Skill(rating.mu, rating.sigma)


def rate(skills: Sequence[Skill], finish_positions: Sequence[int]) -> list[Skill]:
    """Update the ratings of one race's cars from their finish positions (1 = winner)."""
    if len(skills) != len(finish_positions) or len(skills) < 2:
        raise ValueError("rate needs two or more cars, each with a finish position")
    teams = [[_MODEL.rating(mu=s.mu, sigma=s.sigma)] for s in skills]
    updated = _MODEL.rate(teams, ranks=[float(p) for p in finish_positions])
    out = []
    for old, (new,) in zip(skills, updated, strict=True):
        if not (math.isfinite(new.mu) and math.isfinite(new.sigma)):
            raise ValueError("rating update produced a non-finite value")
        out.append(Skill(new.mu, new.sigma, old.races + 1))
    return out


def standing_row(standing: Standing) -> dict[str, Any]:
    """A leaderboard row as plain JSON: the API's columns plus ``racer_id``.

    Every figure, the racing metrics included, is the counting race's.

    The API's ``LeaderboardRow`` reads it (dropping ``racer_id``); the scheduler stores it
    as an event's final standings.
    """
    r, skill = standing.result, standing.skill
    return {
        "rank": standing.rank,
        "racer_id": r.racer_id,
        "alias": r.alias,
        "model_id": r.model_id,
        "model_name": r.model_name,
        "race_id": r.race_id,
        "status": r.status,
        "lap_count": r.laps,
        "best_lap_ms": r.best_ms,
        "average_lap_ms": r.average_ms,
        "total_time_ms": r.total_ms,
        "off_track_count": r.off_track_count,
        "collision_count": r.crash_count,
        "reset_count": r.reset_count,
        "overtakes": r.overtakes,
        "times_overtaken": r.times_overtaken,
        "at_fault_collisions": r.at_fault_collisions,
        "laps_led": r.laps_led,
        "gap_to_winner_ms": r.gap_to_winner_ms,
        "ranking_score_ms": standing.score_ms,
        "submission_count": standing.submissions,
        "mu": skill.mu if skill else None,
        "sigma": skill.sigma if skill else None,
        "ordinal": skill.ordinal if skill else None,
    }


def leaderboard(session: Session, event: Event) -> list[Standing]:
    """The event's standings from its stored results, entries and ratings."""
    rows = session.execute(
        select(RaceCar, Race.id, Entry.racer_id, Racer.alias, Model.name)
        .join(Race, RaceCar.race_id == Race.id)
        .join(Entry, RaceCar.entry_id == Entry.id)
        .join(Racer, Entry.racer_id == Racer.id)
        .join(Model, Entry.model_id == Model.id)
        .where(Race.event_id == event.id)
    ).all()
    results = [
        Result(
            racer_id=racer_id,
            alias=alias,
            model_id=car.model_id,
            model_name=model_name,
            race_id=race_id,
            status=car.status,
            laps=car.laps,
            best_ms=car.best_ms,
            average_ms=car.average_ms,
            total_ms=car.total_ms,
            off_track_count=car.off_track_count,
            crash_count=car.crash_count,
            reset_count=car.reset_count,
            distance_m=car.distance_m,
            overtakes=car.overtakes,
            times_overtaken=car.times_overtaken,
            at_fault_collisions=car.at_fault_collisions,
            laps_led=car.laps_led,
            gap_to_winner_ms=car.gap_to_winner_ms,
        )
        for car, race_id, racer_id, alias, model_name in rows
    ]
    counts = dict(
        session.execute(
            select(Entry.racer_id, func.count(Entry.id))
            .where(Entry.event_id == event.id)
            .group_by(Entry.racer_id)
        ).all()
    )
    skills = None
    if event.race_type == "head_to_model":
        skills = {
            r.model_id: Skill(r.mu, r.sigma, r.races)
            for r in session.scalars(select(Rating).where(Rating.event_id == event.id))
        }
        results += _unraced_entries(session, event, {r.model_id for r in results})
    return standings(results, event.ranking_metric, counts, skills)


def _unraced_entries(session: Session, event: Event, raced: set[int]) -> list[Result]:
    """Head-to-head entries with no race yet, so that they show on the board."""
    rows = session.execute(
        select(Entry.racer_id, Entry.model_id, Racer.alias, Model.name)
        .join(Racer, Entry.racer_id == Racer.id)
        .join(Model, Entry.model_id == Model.id)
        .where(Entry.event_id == event.id)
    ).all()
    return [
        unraced(racer_id, alias, model_id, name)
        for racer_id, model_id, alias, name in rows
        if model_id not in raced
    ]


def lineup_key(cars: Iterable[RaceCar]) -> tuple[int, ...]:
    """Who raced, whatever the grid order: sorted model ids, 0 for each bot."""
    return tuple(sorted(c.model_id or 0 for c in cars))


def rated_twin(session: Session, race: Race) -> Race | None:
    """An earlier race of the event with ``race``'s lineup, ruleset and seed, if any.

    Such a race was rated already: racing it again repeats one observation.
    """
    session.flush()  # ``race`` needs its id
    earlier = session.scalars(
        select(Race)
        .options(selectinload(Race.cars))
        .where(
            Race.event_id == race.event_id,
            Race.ruleset_hash == race.ruleset_hash,
            Race.seed == race.seed,
            Race.id < race.id,
        )
        .order_by(Race.id)
    )
    key = lineup_key(race.cars)
    return next((r for r in earlier if lineup_key(r.cars) == key), None)


def rate_race(session: Session, race: Race) -> None:
    """Update the head-to-head ratings of the models in ``race`` (Plackett-Luce).

    A race that adds no information is not rated (and is logged): one with fewer than two
    models, or one whose (lineup, ruleset, seed) an earlier race of the event already had.
    Joins the caller's transaction (the worker's result transaction); does not commit.
    """
    cars = [c for c in race.cars if c.model_id is not None]
    if len(cars) < 2:
        return
    twin = rated_twin(session, race)
    if twin is not None:
        log.info(
            "race %d not rated: race %d had the same lineup %s, ruleset and seed %d",
            race.id,
            twin.id,
            list(lineup_key(race.cars)),
            race.seed,
        )
        return
    held = {
        r.model_id: r
        for r in session.scalars(
            select(Rating).where(
                Rating.event_id == race.event_id, Rating.model_id.in_([c.model_id for c in cars])
            )
        )
    }
    start = initial_skill()
    skills = [
        Skill(held[c.model_id].mu, held[c.model_id].sigma, held[c.model_id].races)
        if c.model_id in held
        else start
        for c in cars
    ]
    updated = rate(skills, [c.finish_position for c in cars])
    for car, skill in zip(cars, updated, strict=True):
        row = held.get(car.model_id) or Rating(event_id=race.event_id, model_id=car.model_id)
        row.mu, row.sigma, row.races = skill.mu, skill.sigma, skill.races
        session.add(row)
    bump_results_version(session, race.event_id)
