"""``CarSpec``: the numbers of the 1/18 scale car, the one place they are written.

The car is DeepRacer's simulated car as deepracer-simapp v5.3.3b (the ROS1/Gazebo
simulator every historical leaderboard ran on) builds and drives it. Each number below
names its source; ``docs/arena.md`` ("The car") tabulates them with the measured
responses. Paths are in simapp's repository:

* ``urdf``: ``bundle/urdf/deepracer/deepracer_single_cam.urdf``;
* ``control``: ``racecar_control_kinematics.yaml`` in
  ``bundle/src/deepracer_simulation_environment/config/``;
* ``gazebo``: ``bundle/urdf/deepracer/racecar.gazebo``;
* ``ctrl``: ``bundle/markov/agent_ctrl/rollout_agent_ctrl.py``, ``utils.py`` and ``constants.py``.

Kept apart from :mod:`arena.car` (the PyBullet body) so that code that only needs the
numbers — the action-space limits, the drivers, the renderer — reads them without
importing PyBullet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class CarSpec:
    """Dimensions (m), masses (kg), friction, drivetrain and steering of one car.

    ``max_steering_deg``, ``min_speed`` and ``max_speed`` are what the car can be
    commanded, hence also the limits of every action space; :attr:`top_speed` is what
    it can reach.
    """

    # Body. urdf: wheel joints at x -0.081663 / +0.082311 (lines 81, 178), y +-0.08105
    # rear / +-0.079601 front (lines 81, 134, 178, 277).
    wheelbase: float = 0.164
    track: float = 0.16
    # urdf masses: chassis 5.0 (line 16), each wheel 0.34055 (line 47), each steering
    # hinge 0.1 (line 153): 6.56 kg in all.
    chassis_mass: float = 5.0
    wheel_mass: float = 0.34055
    knuckle_mass: float = 0.1
    # gazebo: mu1 = mu2 = 0.5 on every wheel (lines 12-13, 21-22, 30-31, 39-40).
    wheel_friction: float = 0.5
    length: float = 0.3235
    width: float = 0.196
    height: float = 0.16  # chassis collision box, from 0.02 m to 0.18 m above the ground
    model_point_ahead: float = 0.14
    # ctrl constants.py lines 40-44: steering clipped to +-30 deg, speed to [0.1, 4] m/s.
    max_steering_deg: float = 30.0
    min_speed: float = 0.1
    max_speed: float = 4.0
    # Drivetrain. ctrl utils.py get_wheel_radius (line 212, 0.035 for simapp >= 3) and
    # rollout_agent_ctrl.py line 687: every wheel's target spin is speed / 0.035 rad/s.
    wheel_radius: float = 0.035
    # The collision wheels roll at about 0.036 m (racing-rules.md, "How it moves"), so
    # the car moves 0.036 / 0.035 times the commanded speed.
    rolling_radius: float = 0.036
    # urdf: every wheel joint's <limit effort="10" velocity="100"/> (lines 90-91, 143-144,
    # 242-243, 341-342). The velocity limit clips the target spin (100 rad/s: 3.6 m/s);
    # the 10 N m torque spins a wheel far past the tyre's grip, so grip limits the drive.
    max_wheel_spin: float = 100.0
    wheel_torque: float = 10.0
    # Steering. control lines 26-34: both hinges get the same target angle (no
    # Ackermann) through a position PID p 1.0, d 0.5 of at most 10 N m (urdf lines
    # 189, 288). Derived, not read: the hinge and its wheel hold about 2.6e-4 kg m^2
    # about the steering axis (urdf izz 0.00026046 + 4e-6), so I s^2 + d s + p has
    # roots near -2.0 and -1900 1/s: a first-order lag of time constant d / p = 0.5 s.
    steering_time_constant: float = 0.5
    steering_torque: float = 10.0

    @property
    def centre_ahead(self) -> float:
        """How far the footprint centre (and centre of mass) lies ahead of the car origin."""
        return self.wheelbase / 2.0

    @property
    def top_speed(self) -> float:
        """The fastest the wheels can drive the car (m/s): their spin limit times radius."""
        return min(self.max_speed / self.wheel_radius, self.max_wheel_spin) * self.rolling_radius

    def wheel_spin(self, speed: float) -> float:
        """Target spin (rad/s) of every wheel for a commanded ``speed``, clipped as simapp does."""
        speed = min(max(float(speed), self.min_speed), self.max_speed)
        return min(speed / self.wheel_radius, self.max_wheel_spin)

    def rear_axle(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The car origin (rear-axle centre) of a car whose model point is at ``(x, y)``."""
        return (
            x - self.model_point_ahead * math.cos(yaw),
            y - self.model_point_ahead * math.sin(yaw),
        )


DEFAULT_CAR = CarSpec()
"""The car every race drives (DeepRacer's 1/18 car)."""
