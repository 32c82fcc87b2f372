"""Simple non-learning drivers: pure pursuit along a lane at a set speed.

``LaneFollower`` steers the bot cars of head-to-bot races and is the built-in ``bot``
driver of ``slipstream race``; :class:`LaneFollowerPolicy` wraps it in the ``Policy``
protocol for a controlled car (it reads the DeepRacer params, not the sensors).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from arena.actions import MAX_SPEED, MAX_STEERING_DEG, ContinuousActionSpace, DiscreteActionSpace
from arena.car_spec import DEFAULT_CAR, CarSpec
from tracks.track import Track


def pursuit_steering(car: CarSpec, x: float, y: float, yaw: float, target: np.ndarray) -> float:
    """Pure-pursuit steering (deg, within the car's lock) from the rear axle at ``(x, y)``,
    heading ``yaw``, onto the arc through ``target`` ``(2,)``."""
    dx, dy = target[0] - x, target[1] - y
    alpha = math.atan2(dy, dx) - yaw
    chord = max(math.hypot(dx, dy), 1e-6)
    steer = math.degrees(math.atan2(2.0 * car.wheelbase * math.sin(alpha), chord))
    return float(np.clip(steer, -car.max_steering_deg, car.max_steering_deg))


class LaneFollower:
    """Pure pursuit on a lateral offset from the centre line.

    Args:
        track: the track (in its driving direction).
        speed: target speed, m/s.
        lookahead: pursuit distance along the track, metres.
        lane: 'center', 'inner', 'outer' or a lateral offset in metres (left positive).
        car: the car it steers.
    """

    def __init__(
        self,
        track: Track,
        speed: float,
        lookahead: float = 0.6,
        lane: str | float = "center",
        car: CarSpec = DEFAULT_CAR,
    ) -> None:
        self.track = track
        self.speed = speed
        self.lookahead = lookahead
        self.lane = lane
        self.car = car

    def command(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        """``(steering_deg, speed)`` towards the lane point ``lookahead`` metres ahead."""
        arc = float(self.track.project(np.array([[x, y]])).arc_length[0])
        target, _ = self.track.pose_at(np.array([arc + self.lookahead]), self.lane)
        return pursuit_steering(self.car, x, y, yaw, target[0]), self.speed


def nearest_action(
    space: DiscreteActionSpace | ContinuousActionSpace, steer: float, speed: float
) -> Any:
    """The action of ``space`` closest to the command ``(steer, speed)``."""
    if isinstance(space, DiscreteActionSpace):
        costs = [
            ((a.steering_angle - steer) / MAX_STEERING_DEG) ** 2
            + ((a.speed - speed) / MAX_SPEED) ** 2
            for a in space.actions
        ]
        return int(np.argmin(costs))
    s, v = space.steering_angle, space.speed
    a0 = 2.0 * (steer - s.low) / (s.high - s.low) - 1.0
    a1 = 2.0 * (speed - v.low) / (v.high - v.low) - 1.0
    return np.clip(np.array([a0, a1], dtype=np.float32), -1.0, 1.0)


class LaneFollowerPolicy:
    """A ``Policy`` that follows the centre line at a set speed (needs the race params)."""

    needs_params = True

    def __init__(
        self,
        track: Track,
        space: DiscreteActionSpace | ContinuousActionSpace,
        speed: float | None = None,
    ) -> None:
        self.space = space
        self.follower = LaneFollower(track, speed if speed is not None else space.max_speed)

    def reset(self) -> None:
        """Stateless."""

    def act(self, observation: dict[str, Any], params: dict[str, Any] | None = None) -> Any:
        """Steer from the model point and heading in ``params``."""
        if params is None:
            raise ValueError("LaneFollowerPolicy needs the race params")
        yaw = math.radians(params["heading"])
        # params give the model point; pursue from the rear axle behind it.
        x, y = self.follower.car.rear_axle(params["x"], params["y"], yaw)
        steer, speed = self.follower.command(x, y, yaw)
        return nearest_action(self.space, steer, speed)
