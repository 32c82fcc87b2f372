"""The params' object keys: nearest objects behind and ahead, and per-car views of a scene."""

from __future__ import annotations

import math

import numpy as np

from arena.params import ObjectsView, closest_objects, object_in_camera
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
