"""Ranking and ratings as pure functions (no server), and the one leaderboard row shape."""

from __future__ import annotations

import pytest

from league.ranking import Result, Skill, initial_skill, rate, standing_row, standings
from league.schemas import LeaderboardRow


def result(racer: int, model: int, status: str = "finished", laps: int = 3, **ms: int) -> Result:
    times = {"best_ms": 9000, "average_ms": 10000, "total_ms": 30000, **ms}
    return Result(
        racer_id=racer,
        alias=f"r{racer}",
        model_id=model,
        model_name=f"m{model}",
        race_id=model,
        status=status,
        laps=laps,
        off_track_count=0,
        crash_count=0,
        reset_count=0,
        distance_m=10.0 * laps,
        **times,
    )


@pytest.mark.parametrize(("metric", "winner"), [("total", 1), ("best", 2), ("average", 3)])
def test_metric_decides(metric: str, winner: int) -> None:
    results = [
        result(1, 1, total_ms=27000, best_ms=8800, average_ms=9100),
        result(2, 2, total_ms=28000, best_ms=8000, average_ms=9200),
        result(3, 3, total_ms=29000, best_ms=8900, average_ms=9000),
    ]
    assert standings(results, metric, {})[0].result.racer_id == winner


def test_best_result_per_racer_and_dnf_last() -> None:
    results = [
        result(1, 1, total_ms=40000),
        result(1, 2, total_ms=31000),
        result(2, 3, status="dnf", laps=2, total_ms=None),
        result(3, 4, status="time_up", laps=1, total_ms=None),
        result(4, 5, total_ms=35000),
    ]
    rows = standings(results, "total", {1: 2, 4: 1})
    assert [(r.rank, r.result.racer_id) for r in rows] == [(1, 1), (2, 4), (3, 2), (4, 3)]
    assert rows[0].result.model_id == 2 and rows[0].submissions == 2
    assert rows[2].score_ms is None


def test_head_to_head_ranks_by_conservative_rating() -> None:
    results = [result(1, 1, total_ms=20000), result(2, 2, total_ms=30000), result(3, 3)]
    skills = {1: Skill(25.0, 8.0), 2: Skill(30.0, 2.0)}
    rows = standings(results, "total", {}, skills)
    assert [r.result.racer_id for r in rows] == [2, 1, 3]
    assert rows[0].skill.ordinal == pytest.approx(24.0) and rows[2].skill is None


def test_rate_rewards_the_winner() -> None:
    start = initial_skill()
    first, second, third = rate([start, start, start], [1, 2, 3])
    assert first.mu > second.mu > third.mu and first.races == 1
    assert first.sigma < start.sigma
    with pytest.raises(ValueError, match="two or more"):
        rate([start], [1])


@pytest.mark.parametrize("positions", [[3, 2, 1], [2, 1, 3], [3, 1, 2]])
def test_rate_follows_finish_positions_not_listing_order(positions: list[int]) -> None:
    start = initial_skill()
    updated = rate([start, start, start], positions)
    winner, second, third = (updated[positions.index(p)] for p in (1, 2, 3))
    assert winner.mu > second.mu > third.mu


def test_one_row_shape_for_the_api_and_the_final_snapshot() -> None:
    (rated,) = standings([result(1, 7, total_ms=30000)], "total", {1: 2}, {7: Skill(30.0, 2.0)})
    row = standing_row(rated)
    assert set(row) == set(LeaderboardRow.model_fields) | {"racer_id"}
    assert row["racer_id"] == 1 and row["lap_count"] == 3 and row["submission_count"] == 2
    assert row["ranking_score_ms"] == 30000 and row["ordinal"] == pytest.approx(24.0)
    api = LeaderboardRow.model_validate(row).model_dump()
    assert api == {k: v for k, v in row.items() if k != "racer_id"}
    (unrated,) = standings([result(2, 8, status="dnf", total_ms=None)], "total", {})
    assert standing_row(unrated)["mu"] is None and standing_row(unrated)["ranking_score_ms"] is None
