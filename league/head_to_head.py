"""Head-to-head records: per pairing of models in an event, who finished ahead how often.

Every race of the event where both models drove counts once for their pairing (a race of
four models counts for each of its six pairings), whether or not it changed the ratings.
Overtakes count where a car's passes can only have been on the other: in two-car races
(the stored per-car ``overtakes`` does not say whom a car passed in a bigger field).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from itertools import combinations

from sqlalchemy import select
from sqlalchemy.orm import Session

from league.models import Model, Race, RaceCar, Racer


@dataclass(frozen=True)
class Placing:
    """Where one car finished in one race, and how many cars it passed (bots: no model)."""

    race_id: int
    model_id: int | None
    finish_position: int
    overtakes: int


@dataclass(frozen=True)
class Tally:
    """A pairing's record from the first model's side (``model_id`` < ``opponent_id``)."""

    model_id: int
    opponent_id: int
    races: int
    wins: int
    losses: int
    overtakes: int
    overtaken: int


@dataclass(frozen=True)
class HeadToHead:
    """One pairing's record with the models' names and owners, as the event page shows it."""

    model_id: int
    model_name: str
    alias: str
    opponent_id: int
    opponent_name: str
    opponent_alias: str
    races: int
    wins: int
    losses: int
    overtakes: int
    overtaken: int


def tally(placings: Iterable[Placing]) -> list[Tally]:
    """Per pairing: races together, wins and losses (finishing ahead of the other or behind
    it), and overtakes each way in their two-car races.

    Pairings come most-raced first, then by model ids.
    """
    races: dict[int, list[Placing]] = defaultdict(list)
    for placing in placings:
        races[placing.race_id].append(placing)
    counts: dict[tuple[int, int], list[int]] = defaultdict(lambda: [0, 0, 0, 0, 0])
    for cars in races.values():
        duel = len(cars) == 2
        models = sorted((c for c in cars if c.model_id is not None), key=lambda c: c.model_id)
        for a, b in combinations(models, 2):
            if a.model_id == b.model_id:
                continue
            record = counts[(a.model_id, b.model_id)]
            record[0] += 1
            record[1] += a.finish_position < b.finish_position
            record[2] += b.finish_position < a.finish_position
            record[3] += a.overtakes if duel else 0
            record[4] += b.overtakes if duel else 0
    tallies = [Tally(a, b, *record) for (a, b), record in counts.items()]
    return sorted(tallies, key=lambda t: (-t.races, t.model_id, t.opponent_id))


def head_to_head(session: Session, event_id: int) -> list[HeadToHead]:
    """The event's head-to-head records (see :func:`tally`), with names and aliases."""
    rows = session.execute(
        select(RaceCar.race_id, RaceCar.model_id, RaceCar.finish_position, RaceCar.overtakes)
        .join(Race, RaceCar.race_id == Race.id)
        .where(Race.event_id == event_id)
    ).all()
    tallies = tally(Placing(*row) for row in rows)
    ids = {t.model_id for t in tallies} | {t.opponent_id for t in tallies}
    names = {
        model_id: (name, alias)
        for model_id, name, alias in session.execute(
            select(Model.id, Model.name, Racer.alias)
            .join(Racer, Model.owner_id == Racer.id)
            .where(Model.id.in_(ids))
        )
    }
    return [
        HeadToHead(
            model_id=t.model_id,
            model_name=names[t.model_id][0],
            alias=names[t.model_id][1],
            opponent_id=t.opponent_id,
            opponent_name=names[t.opponent_id][0],
            opponent_alias=names[t.opponent_id][1],
            races=t.races,
            wins=t.wins,
            losses=t.losses,
            overtakes=t.overtakes,
            overtaken=t.overtaken,
        )
        for t in tallies
    ]
