"""Simple non-learning drivers: pure pursuit along a lane at a set speed.

``LaneFollower`` steers the bot cars of head-to-bot races and is the built-in ``bot``
driver of ``slipstream race``; :class:`LaneFollowerPolicy` wraps it in the ``Policy``
protocol for a controlled car (it reads the DeepRacer params, not the sensors).
:class:`SteeringLead` is what every driver here does about the car's lagging steering.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from arena.actions import MAX_SPEED, MAX_STEERING_DEG, ContinuousActionSpace, DiscreteActionSpace
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.config import PhysicsConfig
from tracks.raceline import CarLimits
from tracks.track import Track


class SteeringLead:
    """Leads a steering that lags its command (a first-order response of ``time_constant``
    seconds): asks for the angle that brings the wheels to the wanted one within one
    control step, tracking where they are from the commands it gave.

    Call :meth:`command` once per control step with the angle wanted, then :meth:`sent`
    with the angle actually commanded (after any snapping to an action space).
    """

    def __init__(
        self, time_constant: float, lock_deg: float, control_hz: float = PhysicsConfig().control_hz
    ) -> None:
        self.share = 1.0 - math.exp(-1.0 / (control_hz * time_constant))
        self.lock = lock_deg
        self.wheels = 0.0

    def reset(self) -> None:
        """The wheels are straight (start of a race)."""
        self.wheels = 0.0

    def command(self, wanted_deg: float) -> float:
        """The steering command (deg, within the lock) that reaches ``wanted_deg`` soonest."""
        lead = self.wheels + (wanted_deg - self.wheels) / self.share
        return float(np.clip(lead, -self.lock, self.lock))

    def sent(self, command_deg: float) -> None:
        """Record the command given this step: the wheels move their share towards it."""
        command_deg = float(np.clip(command_deg, -self.lock, self.lock))
        self.wheels += (command_deg - self.wheels) * self.share


def pursuit_steering(
    car: CarSpec,
    x: float,
    y: float,
    yaw: float,
    target: np.ndarray,
    wheelbase: float | None = None,
) -> float:
    """Pure-pursuit steering (deg, within the car's lock) from the rear axle at ``(x, y)``,
    heading ``yaw``, onto the arc through ``target`` ``(2,)``.

    ``wheelbase`` is the one the steering geometry uses: the car's own by default, or its
    measured effective wheelbase at its speed (``CarLimits.wheelbase_at``), which
    accounts for the scrub of its wheels in a bend.
    """
    dx, dy = target[0] - x, target[1] - y
    alpha = math.atan2(dy, dx) - yaw
    chord = max(math.hypot(dx, dy), 1e-6)
    base = car.wheelbase if wheelbase is None else wheelbase
    steer = math.degrees(math.atan2(2.0 * base * math.sin(alpha), chord))
    return float(np.clip(steer, -car.max_steering_deg, car.max_steering_deg))


class LaneFollower:
    """Pure pursuit on a lateral offset from the centre line, leading the lagging steering.

    Stateful: :meth:`command` is called once per control step of the car it drives.

    Args:
        track: the track (in its driving direction).
        speed: target speed, m/s.
        lookahead: pursuit distance along the track, metres.
        lane: 'center', 'inner', 'outer' or a lateral offset in metres (left positive).
        car: the car it steers.
        limits: that car's measured limits (its effective wheelbase and steering lag);
            by default ``DEFAULT_CAR``'s, ``CarLimits()``.
    """

    def __init__(
        self,
        track: Track,
        speed: float,
        lookahead: float = 0.6,
        lane: str | float = "center",
        car: CarSpec = DEFAULT_CAR,
        limits: CarLimits | None = None,
    ) -> None:
        self.track = track
        self.speed = speed
        self.lookahead = lookahead
        self.lane = lane
        self.car = car
        limits = limits or CarLimits()
        self.wheelbase = limits.wheelbase_at(speed)
        self.lead = SteeringLead(limits.steering_time_constant, car.max_steering_deg)

    def command(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        """``(steering_deg, speed)`` towards the lane point ``lookahead`` metres ahead."""
        arc = float(self.track.project(np.array([[x, y]])).arc_length[0])
        target, _ = self.track.pose_at(np.array([arc + self.lookahead]), self.lane)
        wanted = pursuit_steering(self.car, x, y, yaw, target[0], self.wheelbase)
        steer = self.lead.command(wanted)
        self.lead.sent(steer)
        return steer, self.speed


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
        """The wheels are straight (start of a race)."""
        self.follower.lead.reset()

    def act(self, observation: dict[str, Any], params: dict[str, Any] | None = None) -> Any:
        """Steer from the model point and heading in ``params``."""
        if params is None:
            raise ValueError("LaneFollowerPolicy needs the race params")
        yaw = math.radians(params["heading"])
        # params give the model point; pursue from the rear axle behind it.
        x, y = self.follower.car.rear_axle(params["x"], params["y"], yaw)
        steer, speed = self.follower.command(x, y, yaw)
        return nearest_action(self.space, steer, speed)
