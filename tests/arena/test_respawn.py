"""Respawns never land on a car: a race always goes on."""

from __future__ import annotations

import numpy as np
import pytest

import arena
from agents.action_spaces import continuous_action_space
from arena.config import NO_VARIATION, RaceConfig, resolve_track
from arena.pursuit import PurePursuitPolicy
from arena.race import run_race
from arena.spawn import (
    RESPAWN_CLEARANCE_M,
    car_footprint,
    place,
    polygon_gap,
    respawn_place,
    room_around,
)
from tracks.catalog import get_track


@pytest.mark.parametrize("seed", [0, 1])
def test_fast_pursuit_car_behind_a_slow_one_both_finish(seed: int) -> None:
    """Issue 13's race: they used to touch, be respawned 7 cm apart and touch forever."""
    slow, fast = continuous_action_space(speed_high=1.0), continuous_action_space(speed_high=3.0)
    config = RaceConfig.build(
        track="slipstream_speedway",
        race_type="head_to_model",
        laps=2,
        seed=seed,
        variation={"shuffle_grid": False},
        cars=[{"name": "slow", "action_space": slow}, {"name": "fast", "action_space": fast}],
    )
    track, _ = resolve_track(config)
    drivers = {"slow": PurePursuitPolicy(track, slow), "fast": PurePursuitPolicy(track, fast)}
    result = run_race(config, drivers, record_trace=False)
    for name in ("slow", "fast"):
        car = result.car(name)
        assert car.status == "finished" and car.laps == 2, car
    assert result.car("fast").crash_count >= 1  # they did meet


def test_a_released_car_has_a_car_length_of_room() -> None:
    config = arena.make_config(race_type="head_to_model", num_cars=4, laps=3, time_limit_s=60.0)
    env = arena.parallel_env(config=config)
    env.reset(seed=2)
    rng = np.random.default_rng(2)
    releases = 0
    for _ in range(900):
        held = {a for a in env.agents if env._cars[a].hold is not None}
        actions = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
        env.step(actions)
        for agent in held & set(env.agents):
            if env._cars[agent].hold is None:  # released: it drives from here next step
                releases += 1
                mine = env._cars[agent].car.footprint()
                for other, live in env._cars.items():
                    if other != agent and not live.parked:
                        assert polygon_gap(mine, live.car.footprint()) >= RESPAWN_CLEARANCE_M - 1e-3
        if not env.agents:
            break
    assert releases >= 5
    env.close()


def test_cars_respawned_in_the_same_step_choose_in_race_order() -> None:
    """Two cars leave the track in the same step, 25 cm apart (too close for both to
    come back at their own spots): the race leader gets its own spot, the other gives
    way behind it. The leader is car1, listed (and starting) second, so neither the
    listed order nor the grid order picks the same car."""
    config = arena.make_config(
        race_type="head_to_model", num_cars=2, laps=1, time_limit_s=30.0, variation=NO_VARIATION
    )
    env = arena.parallel_env(config=config)
    env.reset()
    track = env.track
    for name, arc in (("car0", 3.0), ("car1", 3.25)):  # 0.8 m outside the right border
        (x, y), _ = track.pose_at(arc)
        outside = -(0.5 * track.project(np.array([[x, y]])).track_width[0] + 0.8)
        spot = place(track, arc, outside)
        env._cars[name].car.teleport(spot.x, spot.y, spot.yaw)
    _, _, _, _, infos = env.step({"car0": 4, "car1": 4})
    assert {infos[a]["episode_status"] for a in ("car0", "car1")} == {"off_track"}
    assert infos["car1"]["distance"] > infos["car0"]["distance"]  # car1 leads the race
    left = {a: np.array([[infos[a]["params"]["x"], infos[a]["params"]["y"]]]) for a in infos}
    leader_arc = float(track.project(left["car1"]).arc_length[0])
    own = place(track, leader_arc, "outer")  # right of centre on this ccw loop
    poses = env.car_poses()
    assert poses["car1"][:2] == pytest.approx((own.x, own.y), abs=1e-6)
    back = env._cars["car0"].car.footprint()
    assert polygon_gap(back, env._cars["car1"].car.footprint()) >= RESPAWN_CLEARANCE_M - 1e-3
    back_arc = float(track.project(np.array([poses["car0"][:2]])).arc_length[0])
    assert track.arc_delta(leader_arc, back_arc) < 0.0  # behind the leader
    env.close()


def test_respawn_place_goes_to_the_first_free_spot_behind() -> None:
    track = get_track("beginner_loop")
    own = place(track, 5.0, "inner")
    assert respawn_place(track, 5.0, own.offset) == own  # nothing in the way
    blocker = car_footprint(place(track, 5.05, own.offset))
    spot = respawn_place(track, 5.0, own.offset, taken=[blocker])
    assert room_around(car_footprint(spot), [blocker]) >= RESPAWN_CLEARANCE_M
    assert spot.offset != own.offset  # the other lane was free
    both_lanes = [blocker, car_footprint(place(track, 5.0, "outer"))]
    spot = respawn_place(track, 5.0, own.offset, taken=both_lanes)
    assert room_around(car_footprint(spot), both_lanes) >= RESPAWN_CLEARANCE_M
    assert -2.0 < track.arc_delta(5.0, spot.arc) < 0.0  # behind the traffic, not far


def test_polygon_gap() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert polygon_gap(square, square + (1.5, 0.0)) == pytest.approx(0.5)
    assert polygon_gap(square, square + (2.0, 2.0)) == pytest.approx(np.sqrt(2.0))
    assert polygon_gap(square, square + (0.5, 0.5)) == 0.0
