"""``run_race`` on a real two-car race: finishing order, gaps and racing metrics, and the
stored form of a result (older results without racing metrics still load)."""

from __future__ import annotations

import pytest

from agents.action_spaces import continuous_action_space
from arena.cli import print_results
from arena.config import RaceConfig, resolve_track
from arena.drivers import LaneFollowerPolicy
from arena.pursuit import PurePursuitPolicy
from arena.race import RaceResult, run_race
from arena.spawn import GRID_GAP_M

TRACK = "slipstream_speedway"


def test_cars_that_did_not_finish_are_placed_by_laps_then_distance() -> None:
    """Three laps in 12 s: nobody finishes. ``sprinter`` (1.8 m/s, inner lane, front slot)
    laps ``crawler`` (0.5 m/s) and ``straggler`` (0.15 m/s), which both keep to the outer
    lane, so nobody touches: one lap beats none, and between no laps the longer way
    driven comes first (names sort the other way round: ``crawler`` < ``sprinter``)."""
    plan = {"sprinter": (1.8, "inner"), "crawler": (0.5, "outer"), "straggler": (0.15, "outer")}
    space = continuous_action_space(speed_low=0.1, speed_high=2.0)
    config = RaceConfig.build(
        track="beginner_loop",
        race_type="head_to_model",
        laps=3,
        time_limit_s=12.0,
        variation={"shuffle_grid": False},
        cars=[{"name": name, "sensors": ("sector_lidar",), "action_space": space} for name in plan],
    )
    track, _ = resolve_track(config)
    policies = {}
    for name, (speed, lane) in plan.items():
        policies[name] = LaneFollowerPolicy(track, space, speed=speed)
        policies[name].follower.lane = lane
    result = run_race(config, policies, record_trace=False)
    sprinter, crawler, straggler = (result.car(name) for name in plan)
    assert {car.status for car in result.cars} == {"time_up"}
    assert all(event["kind"] != "contact" for event in result.events)
    assert sprinter.laps == 1 and crawler.laps == straggler.laps == 0
    assert crawler.distance > straggler.distance + 1.0
    assert result.finish_order == ["sprinter", "crawler", "straggler"]
    positions = [car.finish_position for car in (sprinter, crawler, straggler)]
    assert positions == [1, 2, 3]
    assert all(car.gap_to_winner is None for car in result.cars)


def _duel(seed: int) -> RaceResult:
    """A pure-pursuit car capped at 3 m/s starting behind one capped at 0.7 m/s (grid kept
    in the listed order: ``slow`` in front, on the inner lane). Both follow the same racing
    line: the fast car gets by on the outside before the lines merge, then laps the slow
    one, running into it from behind."""
    caps = {"slow": 0.7, "fast": 3.0}
    spaces = {name: continuous_action_space(speed_high=cap) for name, cap in caps.items()}
    config = RaceConfig.build(
        track=TRACK,
        race_type="head_to_model",
        mode="race",
        laps=2,
        time_limit_s=120.0,
        seed=seed,
        variation={"shuffle_grid": False},
        cars=[
            {"name": name, "sensors": ("sector_lidar",), "action_space": space}
            for name, space in spaces.items()
        ],
    )
    track, _ = resolve_track(config)
    policies = {name: PurePursuitPolicy(track, space) for name, space in spaces.items()}
    return run_race(config, policies)


@pytest.fixture(scope="module")
def duel() -> RaceResult:
    return _duel(seed=3)


def test_the_faster_car_passes_the_slower_one_on_track_and_wins(duel: RaceResult) -> None:
    fast, slow = duel.car("fast"), duel.car("slow")
    assert fast.overtakes >= 1 and slow.times_overtaken >= 1
    assert fast.overtakes == slow.times_overtaken and slow.overtakes == fast.times_overtaken
    passes = [e for e in duel.events if e["kind"] == "overtake"]
    assert len(passes) == fast.overtakes + slow.overtakes
    assert [e["t"] for e in duel.events] == sorted(e["t"] for e in duel.events)
    assert fast.status == "finished" and fast.total_time is not None
    if slow.total_time is not None:
        assert fast.total_time < slow.total_time
    assert duel.finish_order == ["fast", "slow"]
    assert (fast.finish_position, slow.finish_position) == (1, 2)
    assert fast.laps_led == duel.config.laps and slow.laps_led == 0


def test_each_result_says_where_its_car_started_on_the_grid(duel: RaceResult) -> None:
    slow, fast = duel.car("slow"), duel.car("fast")  # listed order: slow in the front slot
    assert slow.grid_offset == 0.0
    assert fast.grid_offset == pytest.approx(-GRID_GAP_M, abs=0.1)


def test_gaps_are_measured_to_the_winner(duel: RaceResult) -> None:
    winner = duel.car(duel.finish_order[0])
    assert winner.gap_to_winner == 0.0
    for car in duel.cars:
        if car.total_time is None:
            assert car.gap_to_winner is None
        else:
            assert car.gap_to_winner == pytest.approx(car.total_time - winner.total_time)


def test_each_contact_counts_once_against_the_car_at_fault(duel: RaceResult) -> None:
    fast = duel.car("fast")
    assert fast.at_fault_collisions >= 1  # it runs into the slow car when lapping it
    blamed = [e for e in duel.events if e["kind"] == "contact" and e["at_fault"]]
    for car in duel.cars:
        assert sum(e["car"] == car.name for e in blamed) == car.at_fault_collisions
        # every contact it caused cost one crash penalty: none was counted per touching step
        assert car.at_fault_collisions == car.crash_count


def test_a_result_round_trips_and_older_results_load_without_metrics(duel: RaceResult) -> None:
    again = RaceResult.from_dict(duel.to_dict())
    assert again.to_json() == duel.to_json() and again.events == duel.events
    old = duel.to_dict()
    del old["events"]
    for car in old["cars"]:
        for key in ("overtakes", "times_overtaken", "at_fault_collisions", "laps_led"):
            del car[key]
        del car["gap_to_winner"], car["grid_offset"]
    loaded = RaceResult.from_dict(old)
    assert loaded.events == [] and loaded.finish_order == duel.finish_order
    assert all(c.overtakes == 0 and c.gap_to_winner is None for c in loaded.cars)
    assert all(c.grid_offset is None for c in loaded.cars)


def test_the_race_table_shows_the_racing_metrics(
    duel: RaceResult, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("COLUMNS", "220")
    print_results(duel)
    lines = capsys.readouterr().out.splitlines()
    header = next(line for line in lines if "overtakes" in line)
    columns = [c.strip() for c in header.strip("┃").split("┃")]
    assert columns[-5:] == ["penalty s", "overtakes", "overtaken", "at-fault", "laps led"]
    assert "gap" in columns
    for car in duel.cars:
        row = next(line for line in lines if f" {car.name} " in line)
        cells = [c.strip() for c in row.strip("│").split("│")]
        shown = dict(zip(columns, cells, strict=True))
        assert shown["overtakes"] == str(car.overtakes)
        assert shown["overtaken"] == str(car.times_overtaken)
        assert shown["at-fault"] == str(car.at_fault_collisions)
        assert shown["laps led"] == str(car.laps_led)
        gap = car.gap_to_winner
        assert shown["gap"] == ("-" if gap is None else f"+{gap:.3f}")
