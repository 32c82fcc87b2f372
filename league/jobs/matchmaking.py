"""Head-to-model matchmaking: grids for one round from the models' current ratings.

Like Kaggle's episode scheduling, the least-raced model of the round anchors the next race
and opponents are drawn with weights that favour a close ``mu`` (an even race teaches the
ratings most) and a high ``sigma`` (uncertain ratings need races), damped by how often the
opponent already raced this round and, squared, by how often the two already met (this
round, and in the rounds the caller counts as recent). Closeness is measured against the
ratings' combined uncertainty, so while sigmas are large a distant ``mu`` is hardly held
against a pairing and pairings keep mixing; as sigmas shrink, close ratings meet more.
Every model races at least ``k`` times a round; a race has 2 to ``max_cars`` cars, and a
built-in bot fills the grid when fewer than two models are entered.
"""

from __future__ import annotations

import math
import random
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations
from typing import Any

from league.bots import DEFAULT_BOT

BETA = 25.0 / 6.0  # openskill's default performance spread


@dataclass(frozen=True)
class Candidate:
    """An entered model with its current rating."""

    entry_id: int
    mu: float
    sigma: float


def pair(a: int, b: int) -> frozenset[int]:
    """The key of a pairing of two entries (either order)."""
    return frozenset((a, b))


def pairings(grids: Iterable[Sequence[Mapping[str, Any]]]) -> Counter[frozenset[int]]:
    """How often each pair of entries shares a grid in ``grids`` (bots left out)."""
    met: Counter[frozenset[int]] = Counter()
    for grid in grids:
        ids = [slot["entry_id"] for slot in grid if "entry_id" in slot]
        met.update(pair(a, b) for a, b in combinations(ids, 2))
    return met


def weight(anchor: Candidate, other: Candidate, races: int, met: int = 0) -> float:
    """How much ``other`` is wanted in ``anchor``'s race: close mu (against the combined
    uncertainty), high sigma, few races this round, few meetings with the grid so far."""
    spread = 2 * BETA**2 + anchor.sigma**2 + other.sigma**2
    closeness = math.exp(-((anchor.mu - other.mu) ** 2) / (2 * spread))
    return closeness * other.sigma / ((1 + races) * (1 + met) ** 2) + 1e-9


def _meetings(met: Mapping[frozenset[int], int], grid: Sequence[Candidate], c: Candidate) -> int:
    return sum(met.get(pair(g.entry_id, c.entry_id), 0) for g in grid)


def plan_round(
    candidates: Sequence[Candidate],
    k: int,
    max_cars: int,
    rng: random.Random,
    recent: Mapping[frozenset[int], int] | None = None,
    bot: str = DEFAULT_BOT,
) -> list[list[dict[str, Any]]]:
    """Grids (lists of ``{"entry_id": id}`` / ``{"bot": bot}`` slots) so every model races
    >= ``k`` times.

    ``recent`` counts the meetings of pairs of entries in recent rounds (see
    :func:`pairings`); they damp a pairing as meetings in this round do. ``bot`` names the
    bot (:mod:`league.bots`) that fills a grid of a model entered alone.
    """
    if not candidates:
        return []
    size = max(2, min(max_cars, len(candidates)))
    races = {c.entry_id: 0 for c in candidates}
    met: Counter[frozenset[int]] = Counter(recent or {})
    grids = []
    while min(races.values()) < k:
        anchor = min(candidates, key=lambda c: (races[c.entry_id], -c.sigma, rng.random()))
        pool = [c for c in candidates if c.entry_id != anchor.entry_id]
        grid = [anchor]
        while len(grid) < size and pool:
            weights = [
                weight(anchor, c, races[c.entry_id], _meetings(met, grid, c)) for c in pool
            ]
            pick = rng.choices(pool, weights)[0]
            grid.append(pick)
            pool.remove(pick)
        for car in grid:
            races[car.entry_id] += 1
        slots = [{"entry_id": c.entry_id} for c in grid]
        met.update(pairings([slots]))
        grids.append(slots + [{"bot": bot} for _ in range(size - len(grid))])
    return grids
