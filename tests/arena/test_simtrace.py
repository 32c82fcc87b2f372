"""Step facts, the race trace made of them, and simtrace rows with DeepRacer's meanings."""

from __future__ import annotations

import csv
import math

import pytest

import arena
from arena.config import resolve_track
from arena.drivers import LaneFollowerPolicy
from arena.race import TRACE_COLUMNS, RaceResult, run_race
from arena.simtrace import (
    SIMTRACE_COLUMNS,
    StepFacts,
    race_rows,
    simtrace_row,
    step_facts,
    write_simtrace,
)


class FullLock:
    """-30 deg at 0.8 m/s: leaves the track to the right within a second."""

    def reset(self) -> None: ...

    def act(self, observation):
        return 1


def _info(**overrides) -> dict:
    params = {
        "steering_angle": -30.0,
        "speed": 0.8,
        "all_wheels_on_track": True,
        "closest_waypoints": [6, 7],
        "steps": 12,
        "track_length": 17.5,
    }
    info = {
        "params": params,
        "time": 0.8,
        "progress": 4.25,
        "episode_status": "in_progress",
        "done": False,
        "pause_left": 0.0,
        "crash_count": 0,
    }
    info.update(overrides)
    return info


@pytest.fixture(scope="module")
def off_track_race() -> RaceResult:
    config = arena.make_config(laps=1, time_limit_s=12.0, sensors=("lidar",))
    return run_race(config, {"car0": FullLock()})


@pytest.fixture(scope="module")
def crash_race() -> RaceResult:
    config = arena.make_config(
        race_type="object_avoidance",
        obstacles={"count": 1, "positions": [[15.0, "inner"]]},
        laps=1,
        time_limit_s=9.0,
        sensors=("lidar",),
        penalties={"crash_s": 1.0},
    )
    track, _ = resolve_track(config)
    inner = LaneFollowerPolicy(track, config.cars[0].action_space, speed=0.8)
    inner.follower.lane = "inner"
    return run_race(config, {"car0": inner})


def test_step_facts_read_the_info_the_pose_the_action_and_the_reward() -> None:
    facts = step_facts(_info(), (1.0, 2.0, 0.5, 0.7), 3, 0.25)
    assert facts == StepFacts(
        t=0.8,
        x=1.0,
        y=2.0,
        yaw=0.5,
        speed=0.7,
        steer=-30.0,
        throttle=0.8,
        action=3,
        reward=0.25,
        progress=4.25,
        status="in_progress",
        all_wheels_on_track=True,
        closest_waypoint=7,
        steps=12,
        done=False,
        pause_left=0.0,
        crash_count=0,
        track_len=17.5,
    )
    continuous = step_facts(_info(), (0.0, 0.0, 0.0, 0.0), [0.5, -0.25], 0.0)
    assert continuous.action == [0.5, -0.25]


def test_simtrace_row_has_every_column_with_deepracer_units() -> None:
    info = _info(episode_status="off_track", pause_left=3.0, crash_count=2)
    row = simtrace_row(step_facts(info, (1.0, 2.0, math.pi / 2, 0.7), 3, 0.25), 5, 123.0)
    assert tuple(row) == SIMTRACE_COLUMNS
    assert row["episode"] == 5 and row["steps"] == 12 and row["wall_clock"] == 123.0
    assert (row["X"], row["Y"], row["yaw"]) == (1.0, 2.0, 90.0)
    assert (row["steer"], row["throttle"], row["action"]) == (-30.0, 0.8, 3)
    assert (row["tstamp"], row["track_len"], row["closest_waypoint"]) == (0.8, 17.5, 7)
    assert (row["pause_duration"], row["obstacle_crash_counter"]) == (3.0, 2)
    assert row["episode_status"] == "off_track" and row["done"] is False
    continuous = step_facts(_info(), (0.0, 0.0, 0.0, 0.0), [0.5, -0.25], 0.0)
    assert simtrace_row(continuous, 0, 0.0)["action"] == "[0.5000, -0.2500]"


def test_race_trace_columns_are_the_step_facts(off_track_race: RaceResult) -> None:
    facts = off_track_race.facts["car0"]
    trace = off_track_race.trace["car0"]
    assert tuple(trace) == TRACE_COLUMNS and len(facts) == off_track_race.steps
    for column in TRACE_COLUMNS:
        assert trace[column] == [getattr(f, column) for f in facts], column


def test_race_simtrace_done_steps_and_pause_follow_deepracer(off_track_race: RaceResult) -> None:
    config = off_track_race.config
    rows = race_rows(off_track_race, "car0", episode=2, wall_clock=7.0)
    assert [r["steps"] for r in rows] == list(range(1, len(rows) + 1))
    assert [r["done"] for r in rows] == [False] * (len(rows) - 1) + [True]
    assert {r["episode"] for r in rows} == {2} and {r["wall_clock"] for r in rows} == {7.0}
    statuses = [r["episode_status"] for r in rows]
    first = statuses.index("off_track")
    pause = [r["pause_duration"] for r in rows]
    assert pause[:first] == [0.0] * first
    assert pause[first] == pytest.approx(config.penalties.off_track_s)
    release = statuses.index("in_progress", first)
    dt = config.control_dt
    for i in range(first + 1, release):
        assert statuses[i] == "pause"
        assert pause[i] == pytest.approx(pause[i - 1] - dt)
    assert pause[release] == 0.0
    assert {r["obstacle_crash_counter"] for r in rows} == {0}


def test_race_simtrace_counts_crashes_cumulatively(crash_race: RaceResult) -> None:
    rows = race_rows(crash_race, "car0")
    crashes = 0
    for row in rows:
        crashes += row["episode_status"] == "crashed"
        assert row["obstacle_crash_counter"] == crashes
    assert crashes == crash_race.car("car0").crash_count >= 2


def test_race_rows_need_the_race_run_here(off_track_race: RaceResult, tmp_path) -> None:
    stored = RaceResult.from_dict(off_track_race.to_dict())
    assert "facts" not in off_track_race.to_dict() and stored.trace == off_track_race.trace
    with pytest.raises(ValueError, match="step facts"):
        race_rows(stored, "car0")
    path = write_simtrace(tmp_path / "sim" / "0-iteration.csv", race_rows(off_track_race, "car0"))
    with path.open() as handle:
        read = list(csv.DictReader(handle))
    assert tuple(read[0]) == SIMTRACE_COLUMNS and len(read) == off_track_race.steps
