"""Standings: rank per-car results by an event's metric, and rate head-to-head races.

Lap times from the arena already hold the penalties (a penalised car is frozen while the
clock runs), so the ranking score is the metric itself: total time of the race's laps,
best lap or average lap, in ms. Cars that finished rank before those that did not; those
rank by laps done, then distance. Each racer's best result counts. Head-to-head events rank
by the conservative openskill rating (``ordinal = mu - 3 sigma``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from openskill.models import PlackettLuce

METRIC_FIELD = {"total": "total_ms", "best": "best_ms", "average": "average_ms"}
_MODEL = PlackettLuce()


@dataclass(frozen=True)
class Result:
    """One car's result in one race, with who drove it."""

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
