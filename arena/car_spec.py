"""``CarSpec``: the numbers of the 1/18 scale car, the one place they are written.

Kept apart from :mod:`arena.car` (the PyBullet body) so that code that only needs the
numbers — the action-space limits, the drivers, the renderer, the racing-line limits
built in ``agents`` — reads them without importing PyBullet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class CarSpec:
    """Dimensions (m), masses (kg), friction and motor limits of one car.

    ``max_steering_deg``, ``min_speed`` and ``max_speed`` are what the car can be
    commanded, hence also the limits of every action space.
    """

    wheelbase: float = 0.164
    track: float = 0.16
    wheel_radius: float = 0.035
    chassis_mass: float = 5.0
    wheel_friction: float = 0.5
    length: float = 0.3235
    width: float = 0.196
    height: float = 0.16  # chassis collision box, from 0.02 m to 0.18 m above the ground
    model_point_ahead: float = 0.14
    max_steering_deg: float = 30.0
    min_speed: float = 0.1
    max_speed: float = 4.0
    wheel_mass: float = 0.3
    wheel_torque: float = 0.15  # N m, per wheel velocity motor
    steering_torque: float = 2.0  # N m, per steering position motor
    steering_gain: float = 0.3  # position-motor gain of the steering knuckles

    @property
    def centre_ahead(self) -> float:
        """How far the footprint centre (and centre of mass) lies ahead of the car origin."""
        return self.wheelbase / 2.0

    def rear_axle(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The car origin (rear-axle centre) of a car whose model point is at ``(x, y)``."""
        return (
            x - self.model_point_ahead * math.cos(yaw),
            y - self.model_point_ahead * math.sin(yaw),
        )


DEFAULT_CAR = CarSpec()
"""The car every race drives (DeepRacer's 1/18 car)."""
