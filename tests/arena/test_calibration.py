"""The car measured by driving it: DeepRacer's responses, and the limits the line plans with."""

from __future__ import annotations

import math
from dataclasses import asdict

import pytest

from arena.calibration import calibrate, limits_source
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.pursuit import car_limits
from tracks.raceline import CarLimits

# deepracer-simapp's car, derived from its files (docs/arena.md, "The car"): grip-limited
# drive and braking at 0.5 g, 100 rad/s on a 0.036 m radius, a 0.5 s steering lag.
SIMAPP_SPEED_AT = {0.5: 2.4, 1.0: 3.6}
SIMAPP_TOP = 3.6
SIMAPP_GRIP = 0.5 * 9.81
SIMAPP_TAU = 0.5


@pytest.fixture(scope="module")
def measured():
    return calibrate()


def test_step_responses_are_within_15_percent_of_simapps(measured) -> None:
    for t, speed in SIMAPP_SPEED_AT.items():
        assert measured.launch.at(t) == pytest.approx(speed, rel=0.15), t
    assert 3.5 <= measured.top_speed <= 3.7
    braking = (SIMAPP_TOP - 1.0) / SIMAPP_GRIP
    assert measured.braking.time_to(1.0) == pytest.approx(braking, rel=0.15)
    assert measured.steering_time_constant == pytest.approx(SIMAPP_TAU, rel=0.15)
    lock = DEFAULT_CAR.max_steering_deg
    assert measured.steering.at(1.5) > 0.9 * lock  # it gets there


def test_the_line_plans_with_the_default_cars_measurement(measured) -> None:
    """``tracks`` cannot import the arena, so ``CarLimits()`` holds the default car's
    figures: this fails when the car changes and they are not recalibrated (run
    ``python -m arena.calibration`` and paste what it prints into ``CarLimits``)."""
    fresh, written = asdict(measured.limits()), asdict(CarLimits())
    for key, value in written.items():
        if key == "cornering":
            assert len(fresh[key]) == len(value)
            for got, want in zip(fresh[key], value, strict=True):
                assert got == pytest.approx(want, rel=0.01)
        else:
            assert fresh[key] == pytest.approx(value, rel=0.01), key
    assert car_limits() == CarLimits()


def test_the_printed_defaults_are_the_measured_limits(measured) -> None:
    namespace: dict = {}
    source = "class Limits:\n" + limits_source(measured.limits())
    exec(compile(source, "limits", "exec"), namespace)  # our own output, not a racer's
    printed = namespace["Limits"]
    for key, value in asdict(measured.limits()).items():
        assert getattr(printed, key) == value


def test_a_changed_car_is_measured_again() -> None:
    """A car whose wheels spin at most half as fast tops out at half the speed, launches
    as hard (grip-limited) and plans its line with that."""
    slow = CarSpec(max_wheel_spin=50.0)
    limits = car_limits(slow)
    assert limits.max_speed == pytest.approx(slow.top_speed, rel=0.01)
    assert slow.top_speed == pytest.approx(50.0 * 0.036)
    assert limits.max_accel == pytest.approx(CarLimits().max_accel, rel=0.1)
    assert math.isclose(limits.car_width, slow.width)
