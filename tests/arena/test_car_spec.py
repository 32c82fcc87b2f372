"""``CarSpec`` is the one place of the car's numbers: everything else reads them there."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from arena.actions import ContinuousActionSpace, DiscreteAction
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.config import BotConfig
from arena.render import TopDownRenderer
from tracks.catalog import get_track


def test_model_point_and_rear_axle_are_model_point_ahead_apart() -> None:
    yaw = 0.7
    x, y = DEFAULT_CAR.rear_axle(1.0, 2.0, yaw)
    assert math.hypot(1.0 - x, 2.0 - y) == pytest.approx(DEFAULT_CAR.model_point_ahead)
    assert math.atan2(2.0 - y, 1.0 - x) == pytest.approx(yaw)
    assert CarSpec(model_point_ahead=0.0).rear_axle(1.0, 2.0, yaw) == (1.0, 2.0)


def test_footprint_centre_is_mid_wheelbase() -> None:
    assert DEFAULT_CAR.centre_ahead == DEFAULT_CAR.wheelbase / 2
    assert CarSpec(wheelbase=0.3).centre_ahead == pytest.approx(0.15)


def test_action_spaces_are_bounded_by_the_car() -> None:
    top, lock, slow = DEFAULT_CAR.max_speed, DEFAULT_CAR.max_steering_deg, DEFAULT_CAR.min_speed
    DiscreteAction(steering_angle=-lock, speed=top)
    DiscreteAction(steering_angle=lock, speed=slow)
    for steer, speed in ((lock + 0.1, 1.0), (0.0, top + 0.1), (0.0, slow / 2)):
        with pytest.raises(ValidationError):
            DiscreteAction(steering_angle=steer, speed=speed)
    space = ContinuousActionSpace()
    assert (space.steering_angle.low, space.steering_angle.high) == (-lock, lock)
    assert space.speed.high == top
    BotConfig(speed=top)
    with pytest.raises(ValidationError):
        BotConfig(speed=slow / 2)


def _car_pixels(renderer: TopDownRenderer, x: float, y: float) -> int:
    frame = renderer.frame(cars=[((x, y, 0.0, 0.0), (0.0, 0.0, 1.0, 1.0))])
    return int(np.sum(np.all(frame == (0, 0, 255), axis=-1)))


def test_top_down_renderer_draws_the_car_of_its_spec() -> None:
    track = get_track("beginner_loop")
    (x, y), _ = track.pose_at(0.0)
    standard = TopDownRenderer(track, width=400)
    big = TopDownRenderer(track, width=400, car=CarSpec(length=0.6, width=0.4))
    assert standard.car is DEFAULT_CAR
    scale = standard.scale**2
    body = DEFAULT_CAR.length * DEFAULT_CAR.width - 0.06 * 0.08  # the nose is drawn on top
    assert _car_pixels(standard, x, y) == pytest.approx(body * scale, rel=0.25)
    assert _car_pixels(big, x, y) > 3 * _car_pixels(standard, x, y)
