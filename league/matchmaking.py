"""Head-to-model matchmaking: grids for one round from the models' current ratings.

Like Kaggle's episode scheduling, the least-raced model of the round anchors the next race
and opponents are drawn with weights that favour a close ``mu`` (an even race teaches the
ratings most) and a high ``sigma`` (uncertain ratings need races), damped by how often the
opponent already raced this round. Every model races at least ``k`` times a round; a race
has 2 to ``max_cars`` cars, and a built-in bot fills the grid when fewer than two models
are entered.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

BOT = {"bot": "pursuit"}
BETA = 25.0 / 6.0  # openskill's default performance spread


@dataclass(frozen=True)
class Candidate:
    """An entered model with its current rating."""

    entry_id: int
    mu: float
    sigma: float


def weight(anchor: Candidate, other: Candidate, races: int) -> float:
    """How much ``other`` is wanted in ``anchor``'s race: close mu, high sigma, few races."""
    spread = 2 * BETA**2 + anchor.sigma**2 + other.sigma**2
    closeness = math.exp(-((anchor.mu - other.mu) ** 2) / (2 * spread))
    return closeness * other.sigma / (1 + races) + 1e-9


def plan_round(
    candidates: Sequence[Candidate], k: int, max_cars: int, rng: random.Random
) -> list[list[dict[str, Any]]]:
    """Grids (lists of ``{"entry_id": id}`` / bot slots) so every model races >= ``k`` times."""
    if not candidates:
        return []
    size = max(2, min(max_cars, len(candidates)))
    races = {c.entry_id: 0 for c in candidates}
    grids = []
    while min(races.values()) < k:
        anchor = min(candidates, key=lambda c: (races[c.entry_id], -c.sigma, rng.random()))
        pool = [c for c in candidates if c.entry_id != anchor.entry_id]
        grid = [anchor]
        while len(grid) < size and pool:
            weights = [weight(anchor, c, races[c.entry_id]) for c in pool]
            pick = rng.choices(pool, weights)[0]
            grid.append(pick)
            pool.remove(pick)
        for car in grid:
            races[car.entry_id] += 1
        slots = [{"entry_id": c.entry_id} for c in grid]
        grids.append(slots + [dict(BOT) for _ in range(size - len(grid))])
    return grids
