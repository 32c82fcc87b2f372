"""The params' object keys: nearest objects behind and ahead, and per-car views of a scene."""

from __future__ import annotations

import math

import numpy as np
import pytest

import arena
from arena.params import ObjectsView, closest_objects, heading_degrees, object_in_camera
from arena.sensors_spec import DEFAULT_CAMERA
from tracks.catalog import get_track
from tracks.track import Track


def straight_track(length: float = 10.0) -> Track:
    x = np.linspace(0.0, length, 11)
    zeros = np.zeros_like(x)
    centre = np.stack([x, zeros], axis=1)
    return Track.from_arrays(
        "straight", centre, centre + [0.0, 0.5], centre - [0.0, 0.5], is_loop=False
    )


def test_closest_objects_wrap_around_a_loop() -> None:
    track = get_track("beginner_loop")
    end = track.length - 0.5
    # 1.0 is 1.5 m ahead across the line; end - 0.5 is 0.5 m behind.
    assert closest_objects(track, end, [1.0, end - 0.5, 5.0]) == [1, 0]


def test_closest_objects_on_an_open_track() -> None:
    track = straight_track()
    assert closest_objects(track, 5.0, [7.0, 2.0, 3.0]) == [2, 0]
    assert closest_objects(track, 5.0, [1.0, 2.0]) == [1, 1]  # nothing ahead
    assert closest_objects(track, 5.0, [7.0, 6.0]) == [1, 1]  # nothing behind
    assert closest_objects(track, 5.0, [6.0, 6.0, 4.0, 4.0]) == [2, 0]  # ties: first


def test_a_car_does_not_see_itself_in_the_scene() -> None:
    track = get_track("beginner_loop")
    points, _ = track.pose_at(np.array([1.0, 2.0, 3.0]), "center")
    view = ObjectsView.of(points, np.array([0.0, 90.0, 180.0]), np.ones(3), track.project(points))
    others = view.without(1)
    assert len(others) == 2
    assert others.heading_deg == (0.0, 180.0)
    assert others.distance == (view.distance[0], view.distance[2])
    assert others.location == (view.location[0], view.location[2])


def test_object_in_camera_uses_the_camera_field_of_view() -> None:
    half = math.radians(DEFAULT_CAMERA.hfov_deg / 2)
    inside = (math.cos(half - 0.01), math.sin(half - 0.01))
    outside = (math.cos(half + 0.01), math.sin(half + 0.01))
    assert object_in_camera(0.0, 0.0, 0.0, inside)
    assert not object_in_camera(0.0, 0.0, 0.0, outside)
    assert not object_in_camera(0.0, 0.0, math.pi, inside)  # facing away


# DeepRacer's params contract: every key in every race type, a fresh copy per call, sim_time.

OBJECT_DEFAULTS = {
    "closest_objects": [0, 0],
    "objects_location": [],
    "objects_left_of_center": [],
    "objects_distance": [],
    "objects_distance_from_center": [],
    "objects_heading": [],
    "objects_speed": [],
    "object_in_camera": False,
}


def _step_params(env, action: int = 4) -> dict:
    _, _, _, _, infos = env.step({a: action for a in env.agents})
    return {a: info["params"] for a, info in infos.items()}


def test_a_time_trial_passes_every_object_key_with_deepracer_defaults() -> None:
    env = arena.parallel_env(race_type="time_trial")
    _, infos = env.reset(seed=0)
    for params in (infos["car0"]["params"], _step_params(env)["car0"]):
        for key, default in OBJECT_DEFAULTS.items():
            assert params[key] == default, key
            assert type(params[key]) is type(default), key
    env.close()


def test_each_reward_call_gets_fresh_lists() -> None:
    seen: list[dict] = []

    def greedy(params: dict) -> float:
        seen.append(
            {
                "waypoints": len(params["waypoints"]),
                "closest_waypoints": list(params["closest_waypoints"]),
                "objects_location": list(params["objects_location"]),
            }
        )
        params["waypoints"].append((0.0, 0.0))
        params["closest_waypoints"].append(-1)
        params["objects_location"].clear()
        params["objects_heading"].append(123.0)
        params["steps"] = -5
        return 1.0

    env = arena.parallel_env(race_type="object_avoidance", seed=5, reward_function=greedy)
    env.reset()
    count = len(env.track.waypoints)
    for _ in range(3):
        params = _step_params(env)["car0"]
        # the info's params are not the reward function's: its edits do not leak out
        assert len(params["waypoints"]) == count
        assert len(params["objects_location"]) == 6
        assert len(params["objects_heading"]) == 6
        assert len(params["closest_waypoints"]) == 2
        assert params["steps"] > 0
    assert [s["waypoints"] for s in seen] == [count] * 3
    assert all(len(s["closest_waypoints"]) == 2 for s in seen)
    assert all(len(s["objects_location"]) == 6 for s in seen)
    env.close()


def test_sim_time_advances_by_the_control_period() -> None:
    env = arena.parallel_env(race_type="time_trial")
    _, infos = env.reset(seed=0)
    times = [infos["car0"]["params"]["sim_time"]]
    for _ in range(4):
        times.append(_step_params(env)["car0"]["sim_time"])
    assert all(isinstance(t, float) for t in times)
    dt = env.config.control_dt
    assert np.diff(times) == pytest.approx([dt] * 4)
    env.close()


def test_boxes_report_heading_zero_and_bots_their_heading() -> None:
    boxes = arena.parallel_env(race_type="object_avoidance", seed=5)
    _, infos = boxes.reset()
    assert infos["car0"]["params"]["objects_heading"] == [0.0] * 6
    assert all(speed == 0.0 for speed in infos["car0"]["params"]["objects_speed"])
    boxes.close()

    bots = arena.parallel_env(race_type="head_to_bot", seed=11)
    bots.reset()
    params = _step_params(bots)["car0"]
    assert bots._bots
    headings = params["objects_heading"][-len(bots._bots) :]  # boxes (if any) come first
    for bot, heading in zip(bots._bots, headings, strict=True):
        expected = heading_degrees(bots._snap(bot.car).state.yaw)
        assert (heading - expected + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-6)
    bots.close()
