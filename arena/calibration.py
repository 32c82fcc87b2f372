"""What the car can do, measured by driving it: the racing line's limits come from here.

:func:`calibrate` drives one car alone on a flat floor through four manoeuvres and
measures, physics step by physics step:

* **launch**: from standstill at full command (4 m/s, straight): the top speed it settles
  at and its drive, as the constant acceleration that covers the same distance to 90%
  of the top speed (``v^2 = 2 a d``: what the racing line's forward pass assumes);
* **braking**: from the top speed to the slowest command: the constant deceleration
  that covers the same distance down to a quarter of the top speed;
* **cornering**: steady circles at a grid of steering angles and speeds: the lateral
  acceleration (speed x yaw rate) it holds, as a line falling with the curvature. With
  no differential the four wheels scrub in a bend, so it sits well under the tyres'
  0.5 g, and further the tighter the circle;
* **steering**: a step from straight to full lock at low speed: the knuckle angle's
  time constant (time to 63.2% of the step).

The physics is deterministic, so a car and its physics settings always calibrate to the
same numbers; :func:`calibrate` keeps them per (car, settings) for the process. Nothing
is written to disk: when the car changes, its limits change with it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pybullet as p

from arena.car import Car
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.world import PhysicsSettings, close, create_world
from tracks.raceline import CarLimits

DEFAULT_PHYSICS = PhysicsSettings()
LAUNCH_S = 3.0
BRAKE_S = 2.5
CORNER_STEER_DEG = tuple(5.0 + 2.5 * i for i in range(11))
"""Steering of the circles: 5 to 30 degrees."""
CORNER_SPEEDS = tuple(round(0.5 + 0.1 * i, 1) for i in range(31))
"""Speed commands of the circles: 0.5 to 3.5 m/s."""
ENVELOPE_STEP = 0.02
"""A drop in speed of more than this share ends one step of the envelope's staircase."""
UNDERSTEER_FIT_DEG = 10.0
CORNER_S = 3.0
CORNER_STEADY_S = 0.75
"""Each circle is measured over its last 0.75 s (the steering lag has long settled)."""
STEER_SPEED = 0.5
"""Speed of the steering test (m/s): slow enough that the car never slides."""
STEER_S = 2.5


@dataclass(frozen=True, eq=False)
class Response:
    """A measured time series: ``values`` at ``times`` (s, from the command)."""

    times: np.ndarray
    values: np.ndarray

    def at(self, t: float) -> float:
        """The value at ``t`` seconds (linear between samples)."""
        return float(np.interp(t, self.times, self.values))

    def time_to(self, value: float) -> float:
        """The first time the series reaches ``value`` (rising or falling), or inf."""
        rising = self.values[-1] >= self.values[0]
        hit = self.values >= value if rising else self.values <= value
        return float(self.times[np.argmax(hit)]) if hit.any() else math.inf


@dataclass(frozen=True, eq=False)
class Calibration:
    """A car's measured responses and the limits the racing line plans with (SI units)."""

    top_speed: float
    max_accel: float
    max_brake: float
    cornering: Cornering
    steering_time_constant: float
    launch: Response
    """Speed (m/s) from standstill at full command."""
    braking: Response
    """Speed (m/s) from top speed at the slowest command."""
    steering: Response
    """Knuckle angle (deg) after a step to full left lock at ``STEER_SPEED``."""

    def limits(self, car: CarSpec = DEFAULT_CAR) -> CarLimits:
        """The racing line's :class:`CarLimits` for this car (its width, these figures)."""
        return CarLimits(
            max_speed=round(self.top_speed, 3),
            max_lateral_accel=round(self.cornering.max_lateral_accel, 3),
            cornering=self.cornering.envelope,
            max_accel=round(float(self.max_accel), 3),
            max_brake=round(float(self.max_brake), 3),
            turning_wheelbase=round(self.cornering.turning_wheelbase, 3),
            understeer_gradient=round(self.cornering.understeer_gradient, 4),
            steering_time_constant=round(self.steering_time_constant, 3),
            max_steering_deg=car.max_steering_deg,
            car_width=car.width,
        )


Command = Callable[[float], tuple[float, float]]
"""``(steering deg, speed)`` at ``t`` seconds into a manoeuvre."""


class _Bench:
    """One car alone in a fresh world, stepped at the physics rate."""

    def __init__(self, car: CarSpec, physics: PhysicsSettings) -> None:
        self.client = create_world(physics)
        self.car = Car(self.client, car)
        self.dt = 1.0 / physics.physics_hz

    def run(self, seconds: float, command: Command, read: Callable[[], Any]) -> Response:
        """Apply ``command(t)`` every physics step for ``seconds``; record ``read()`` after each."""
        times, values = [0.0], [read()]
        for i in range(round(seconds / self.dt)):
            self.car.apply_command(*command(i * self.dt))
            p.stepSimulation(physicsClientId=self.client)
            times.append((i + 1) * self.dt)
            values.append(read())
        return Response(np.array(times), np.array(values, dtype=float))

    def speed(self) -> float:
        return self.car.state().speed

    def close(self) -> None:
        close(self.client)


def _distance(response: Response, start: float, end: float) -> float:
    """Distance covered between the times ``start`` and ``end`` (trapezoids)."""
    inside = (response.times >= start) & (response.times <= end)
    return float(np.trapezoid(response.values[inside], response.times[inside]))


def _launch_and_brake(
    bench: _Bench, car: CarSpec
) -> tuple[Response, Response, float, float, float]:
    launch = bench.run(LAUNCH_S, lambda t: (0.0, car.max_speed), bench.speed)
    top = float(np.mean(launch.values[launch.times > LAUNCH_S - 0.5]))
    fast = launch.time_to(0.9 * top)
    accel = (0.9 * top) ** 2 / (2.0 * _distance(launch, 0.0, fast))
    braking = bench.run(BRAKE_S, lambda t: (0.0, car.min_speed), bench.speed)
    slow = braking.time_to(0.25 * top)
    start = braking.values[0]
    brake = (start**2 - (0.25 * top) ** 2) / (2.0 * _distance(braking, 0.0, slow))
    return launch, braking, top, accel, brake


@dataclass(frozen=True, eq=False)
class Cornering:
    """What the circle grid measured (see :func:`_cornering`)."""

    max_lateral_accel: float
    turning_wheelbase: float
    understeer_gradient: float
    envelope: tuple[tuple[float, float], ...]
    """``(curvature, speed)`` rows by rising curvature: the fastest circle at least so tight."""


def _cornering(bench: _Bench) -> Cornering:
    """Steady circles over the grid of steering angles and speed commands.

    Each circle gives a curvature and a speed. The lateral grip is the highest ``v^2 k``
    held; the envelope keeps the circles no other is both faster and tighter than (the
    fastest circle at least so tight). The circles at small steering angles (at most
    ``UNDERSTEER_FIT_DEG``, where the car races) give the steering's effective wheelbase
    ``tan(steer) / curvature`` as a line in ``v^2``: the turning wheelbase at rest and
    the understeer gradient (the wheels scrub more, the faster the car turns).
    """
    circles: list[tuple[float, float]] = []
    lateral, fit = 0.0, []

    def motion() -> tuple[float, float]:
        state = bench.car.state()
        return state.speed, state.yaw_rate

    for steer in CORNER_STEER_DEG:
        for command in CORNER_SPEEDS:
            bench.car.teleport(0.0, 0.0, 0.0)
            runs = bench.run(CORNER_S, lambda t, a=steer, v=command: (a, v), motion)
            v, yaw_rate = np.mean(runs.values[runs.times > CORNER_S - CORNER_STEADY_S], axis=0)
            curvature = abs(float(yaw_rate / v))
            lateral = max(lateral, float(v) ** 2 * curvature)
            circles.append((curvature, float(v)))
            if steer <= UNDERSTEER_FIT_DEG:
                fit.append((float(v) ** 2, math.tan(math.radians(steer)) / curvature))
    envelope: list[tuple[float, float]] = []
    for curvature, v in sorted(circles, key=lambda row: -row[1]):
        row = (round(curvature, 3), round(v, 3))
        if not envelope or row[0] > envelope[-1][0]:
            envelope.append(row)
    # The speed commands' grid makes the frontier a staircase: keep the corner of each
    # step (the tightest circle before the speed drops), the envelope runs between them.
    envelope = [
        row
        for row, after in zip(envelope, [*envelope[1:], None], strict=True)
        if after is None or after[1] < (1.0 - ENVELOPE_STEP) * row[1]
    ]
    gradient, wheelbase = np.polyfit(*np.array(fit).T, 1)
    # A slow car barely slides: its fitted gradient is noise around zero.
    return Cornering(lateral, float(wheelbase), max(float(gradient), 0.0), tuple(envelope))


def _steering(bench: _Bench, car: CarSpec) -> tuple[Response, float]:
    bench.run(1.0, lambda t: (0.0, STEER_SPEED), bench.speed)
    angle = bench.car.steering_angle_deg
    response = bench.run(STEER_S, lambda t: (car.max_steering_deg, STEER_SPEED), angle)
    return response, response.time_to((1.0 - math.exp(-1.0)) * car.max_steering_deg)


@functools.cache
def calibrate(
    car: CarSpec = DEFAULT_CAR, physics: PhysicsSettings = DEFAULT_PHYSICS
) -> Calibration:
    """Drive ``car`` through the four manoeuvres (a fresh world each) and measure it."""
    benches = [_Bench(car, physics) for _ in range(3)]
    try:
        launch, braking, top, accel, brake = _launch_and_brake(benches[0], car)
        cornering = _cornering(benches[1])
        steering, tau = _steering(benches[2], car)
    finally:
        for bench in benches:
            bench.close()
    return Calibration(
        top_speed=top,
        max_accel=accel,
        max_brake=brake,
        cornering=cornering,
        steering_time_constant=tau,
        launch=launch,
        braking=braking,
        steering=steering,
    )


def limits_source(limits: CarLimits) -> str:
    """The fields of ``limits`` as the lines of ``CarLimits``' defaults (``python -m``)."""
    lines = []
    for key, value in asdict(limits).items():
        if key == "cornering":
            rows = "".join(f"        ({k}, {v}),\n" for k, v in value)
            lines.append(f"    cornering: tuple[tuple[float, float], ...] = (\n{rows}    )")
        else:
            lines.append(f"    {key}: float = {value}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(limits_source(calibrate().limits()))
