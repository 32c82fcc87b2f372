"""The built-in drivers steer by pure pursuit with the numbers of the car they drive."""

from __future__ import annotations

import math

import numpy as np
import pytest

from arena.actions import DiscreteAction, DiscreteActionSpace
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.drivers import LaneFollower, LaneFollowerPolicy, nearest_action, pursuit_steering
from tracks.catalog import get_track


def test_pursuit_steering_turns_towards_the_target_within_the_lock() -> None:
    ahead, left = np.array([1.0, 0.0]), np.array([1.0, 0.2])
    assert pursuit_steering(DEFAULT_CAR, 0.0, 0.0, 0.0, ahead) == 0.0
    steer = pursuit_steering(DEFAULT_CAR, 0.0, 0.0, 0.0, left)
    assert 0.0 < steer < DEFAULT_CAR.max_steering_deg
    assert pursuit_steering(DEFAULT_CAR, 0.0, 0.0, math.pi, left) < 0.0  # target behind-right
    # The arc through the target has radius R = d^2 / (2 y); the bicycle steers atan(L / R).
    radius = (1.0**2 + 0.2**2) / (2 * 0.2)
    assert steer == pytest.approx(math.degrees(math.atan(DEFAULT_CAR.wheelbase / radius)))
    longer = CarSpec(wheelbase=2 * DEFAULT_CAR.wheelbase)
    assert pursuit_steering(longer, 0.0, 0.0, 0.0, left) > steer
    side = np.array([0.0, 0.2])  # a circle tighter than full lock
    assert pursuit_steering(DEFAULT_CAR, 0.0, 0.0, 0.0, side) == DEFAULT_CAR.max_steering_deg
    tight = CarSpec(max_steering_deg=10.0)
    assert pursuit_steering(tight, 0.0, 0.0, 0.0, -side) == -10.0


def test_lane_follower_steers_with_its_car() -> None:
    track = get_track("beginner_loop")
    (x, y), yaw = track.pose_at(1.0, "outer")
    follower = LaneFollower(track, 1.0, lane="inner")
    assert follower.car is DEFAULT_CAR
    steer, speed = follower.command(float(x), float(y), float(yaw))
    assert speed == 1.0 and steer != 0.0
    gentle = LaneFollower(track, 1.0, lane="inner", car=CarSpec(max_steering_deg=abs(steer) / 2))
    assert abs(gentle.command(float(x), float(y), float(yaw))[0]) == pytest.approx(abs(steer) / 2)


def test_lane_follower_policy_pursues_from_the_rear_axle() -> None:
    track = get_track("beginner_loop")
    space = DiscreteActionSpace(
        actions=(
            DiscreteAction(steering_angle=-30.0, speed=1.0),
            DiscreteAction(steering_angle=0.0, speed=1.0),
            DiscreteAction(steering_angle=30.0, speed=1.0),
        )
    )
    policy = LaneFollowerPolicy(track, space)
    (x, y), yaw = track.pose_at(0.2)
    model = DEFAULT_CAR.model_point_ahead * np.array([math.cos(yaw), math.sin(yaw)])
    params = {"x": x + model[0], "y": y + model[1], "heading": math.degrees(yaw)}
    follower = policy.follower
    expected = nearest_action(space, *follower.command(float(x), float(y), float(yaw)))
    assert policy.act({}, params) == expected == 1


def test_nearest_action_weighs_steering_and_speed_by_the_car_limits() -> None:
    space = DiscreteActionSpace(
        actions=(
            DiscreteAction(steering_angle=0.0, speed=1.0),
            DiscreteAction(steering_angle=12.0, speed=4.0),
        )
    )
    # 12 deg of 30 is closer than 3 m/s of 4: the first action, though 12 > 3 in raw units.
    assert nearest_action(space, 12.0, 1.0) == 0
