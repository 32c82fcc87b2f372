"""Sanity tests of the car model: speed, turning circle, limits, geometry, resets."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest

from arena.car import Car, CarState
from arena.car_spec import CarSpec
from arena.world import PhysicsSettings, close, create_world, step

SETTINGS = PhysicsSettings()
SPEC = CarSpec()


@pytest.fixture
def client() -> Iterator[int]:
    cid = create_world(SETTINGS)
    yield cid
    close(cid)


def drive(car: Car, client: int, steering: float, speed: float, steps: int) -> list[CarState]:
    states = []
    for _ in range(steps):
        car.apply_command(steering, speed)
        step(client, SETTINGS)
        states.append(car.state())
    return states


def fit_circle(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares circle through (n, 2) points: centre and radius."""
    a = np.c_[2.0 * points, np.ones(len(points))]
    b = (points**2).sum(axis=1)
    cx, cy, c = np.linalg.lstsq(a, b, rcond=None)[0]
    return np.array([cx, cy]), math.sqrt(c + cx**2 + cy**2)


def test_straight_line_settles_at_top_speed(client: int) -> None:
    car = Car(client)
    states = drive(car, client, 0.0, 4.0, 75)
    settled = np.mean([s.speed for s in states[-15:]])
    assert settled == pytest.approx(SPEC.top_speed, rel=0.01)  # 100 rad/s x 0.036 m
    end = states[-1]
    assert end.x > 10.0
    assert abs(end.y) < 0.05 and abs(end.yaw) < 0.01  # drives straight


def test_commands_from_3_5_mps_up_drive_alike() -> None:
    """The wheel spin limit (100 rad/s) clips 3.5 / 0.035 m and anything faster."""
    ends = []
    for speed in (3.5, 4.0):
        cid = create_world(SETTINGS)
        ends.append(drive(Car(cid), cid, 0.0, speed, 30)[-1])
        close(cid)
    assert ends[0].x == pytest.approx(ends[1].x, abs=1e-9)
    assert ends[0].speed == pytest.approx(ends[1].speed, abs=1e-9)
    cid = create_world(SETTINGS)
    slower = drive(Car(cid), cid, 0.0, 3.0, 30)[-1]
    close(cid)
    assert slower.x < ends[0].x - 0.5


def test_every_wheel_spins_alike_and_both_knuckles_steer_alike(client: int) -> None:
    """simapp's drive: one spin for all four wheels (no differential), one angle for both
    steering hinges (no Ackermann)."""
    car = Car(client)
    drive(car, client, 20.0, 1.5, 20)
    wheels = [s[1] for s in p.getJointStates(car.body_id, [1, 3, 4, 5], physicsClientId=client)]
    knuckles = [s[0] for s in p.getJointStates(car.body_id, [0, 2], physicsClientId=client)]
    assert max(wheels) - min(wheels) < 0.02 * max(wheels)  # the motors hold one target
    assert np.mean(wheels) == pytest.approx(SPEC.wheel_spin(1.5), rel=0.02)
    assert knuckles[0] == pytest.approx(knuckles[1], abs=1e-4)
    assert math.degrees(knuckles[0]) == pytest.approx(car.steering_angle_deg(), abs=1e-3)


def test_steering_lags_its_command_by_the_spec_time_constant(client: int) -> None:
    car = Car(client)
    drive(car, client, 0.0, 0.5, 15)
    tau_steps = round(SPEC.steering_time_constant * SETTINGS.control_hz)
    drive(car, client, 30.0, 0.5, tau_steps)
    elapsed = tau_steps / SETTINGS.control_hz
    expected = 30.0 * (1 - math.exp(-elapsed / SPEC.steering_time_constant))
    assert car.steering_angle_deg() == pytest.approx(expected, rel=0.05)
    drive(car, client, 30.0, 0.5, 3 * tau_steps)
    assert car.steering_angle_deg() > 0.97 * 30.0


def test_speed_is_reached_through_the_drivetrain(client: int) -> None:
    car = Car(client)
    speeds = [s.speed for s in drive(car, client, 0.0, 4.0, 30)]
    assert speeds[0] < 1.0
    assert all(b >= a - 1e-3 for a, b in itertools.pairwise(speeds))
    assert speeds[-1] > 3.5


def test_full_lock_circle_is_wider_than_the_kinematic_one(client: int) -> None:
    """With no differential the wheels scrub: the car turns a wider circle than its
    wheelbase draws, steadily, a little under the commanded speed (the scrub drags)."""
    car = Car(client)
    states = drive(car, client, 30.0, 1.0, 150)
    settled = states[50:]
    points = np.array([[s.x, s.y] for s in settled])
    _, radius = fit_circle(points)
    kinematic = SPEC.wheelbase / math.tan(math.radians(30.0))  # rear-axle path
    assert 1.2 * kinematic < radius < 2.5 * kinematic
    assert all(s.yaw_rate > 0 for s in settled)  # positive steering turns left
    speeds = [s.speed for s in settled]
    assert 0.8 < np.mean(speeds) < 1.0
    assert np.std(speeds) < 0.03  # steady, no solver wobble


def test_negative_steering_turns_right(client: int) -> None:
    car = Car(client)
    end = drive(car, client, -15.0, 1.0, 15)[-1]
    assert end.yaw < -0.3 and end.y < 0.0


def test_commands_are_clipped_to_limits() -> None:
    ends = []
    for steering, speed in [(90.0, 10.0), (30.0, 4.0)]:
        cid = create_world(SETTINGS)
        car = Car(cid)
        ends.append(drive(car, cid, steering, speed, 20)[-1])
        close(cid)
    assert ends[0].x == pytest.approx(ends[1].x, abs=1e-9)
    assert ends[0].speed == pytest.approx(ends[1].speed, abs=1e-9)
    cid = create_world(SETTINGS)
    car = Car(cid)
    slow = drive(car, cid, 0.0, 0.0, 30)[-1]
    close(cid)
    assert slow.speed == pytest.approx(SPEC.min_speed, rel=0.05)


def test_geometry_follows_the_pose(client: int) -> None:
    car = Car(client, x=1.0, y=2.0, yaw=math.pi / 2)
    state = car.state()
    assert (state.x, state.y, state.yaw) == pytest.approx((1.0, 2.0, math.pi / 2), abs=1e-6)
    np.testing.assert_allclose(car.model_point(), [1.0, 2.0 + SPEC.model_point_ahead], atol=1e-6)
    wheels = car.wheel_points()
    half_track = SPEC.track / 2
    expected = [
        [1.0 - half_track, 2.0 + SPEC.wheelbase],
        [1.0 + half_track, 2.0 + SPEC.wheelbase],
        [1.0 - half_track, 2.0],
        [1.0 + half_track, 2.0],
    ]
    np.testing.assert_allclose(wheels, expected, atol=1e-6)
    corners = car.footprint()
    sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    np.testing.assert_allclose(sides, [SPEC.length, SPEC.width] * 2, atol=1e-6)
    np.testing.assert_allclose(corners.mean(axis=0), [1.0, 2.0 + SPEC.wheelbase / 2], atol=1e-6)
    assert corners[:, 1].max() > car.model_point()[1]


def test_snapshot_points_follow_the_spec(client: int) -> None:
    spec = CarSpec(wheelbase=0.2, model_point_ahead=0.05)
    car = Car(client, spec, x=1.0, y=2.0, yaw=0.4)
    snap = car.snapshot()
    ahead = np.array([math.cos(0.4), math.sin(0.4)])
    np.testing.assert_allclose(snap.centre, [1.0, 2.0] + spec.centre_ahead * ahead, atol=1e-6)
    np.testing.assert_allclose(spec.rear_axle(*snap.model_point, 0.4), [1.0, 2.0], atol=1e-6)


def test_teleport_zeroes_motion(client: int) -> None:
    car = Car(client)
    drive(car, client, 30.0, 3.0, 20)
    car.teleport(5.0, -1.0, 1.0)
    state = car.state()
    assert (state.x, state.y, state.yaw) == pytest.approx((5.0, -1.0, 1.0), abs=1e-9)
    assert (state.speed, state.vx, state.vy, state.yaw_rate) == (0.0, 0.0, 0.0, 0.0)
    joints = p.getJointStates(car.body_id, range(6), physicsClientId=client)
    assert all(j[0] == 0.0 and j[1] == 0.0 for j in joints)
    step(client, SETTINGS)
    after = car.state()
    assert math.hypot(after.x - 5.0, after.y + 1.0) < 1e-3 and abs(after.speed) < 0.01


def test_stop_freezes_in_place(client: int) -> None:
    car = Car(client)
    before = drive(car, client, 10.0, 3.0, 20)[-1]
    car.stop()
    held = car.state()
    assert (held.x, held.y, held.yaw) == pytest.approx((before.x, before.y, before.yaw))
    assert (held.speed, held.vx, held.vy, held.yaw_rate) == (0.0, 0.0, 0.0, 0.0)
    for _ in range(15):
        step(client, SETTINGS)
    later = car.state()
    assert math.hypot(later.x - held.x, later.y - held.y) < 5e-3


def run_scripted(seed: int, client: int | None = None) -> list[CarState]:
    """Two cars on random commands that meet, one teleported: their states each step. In a
    fresh client (closed after), or in ``client`` emptied and rebuilt (left open)."""
    rng = np.random.default_rng(seed)
    cid = create_world(SETTINGS, client)
    cars = [Car(cid, x=-1.0, y=0.0), Car(cid, x=1.0, y=0.05, yaw=math.pi)]
    states = []
    for t in range(45):
        for car in cars:
            car.apply_command(rng.uniform(-30, 30), rng.uniform(0.1, 4.0))
        if t == 30:
            cars[0].teleport(0.0, 1.0, 0.5)
        step(cid, SETTINGS)
        states.extend(car.state() for car in cars)
    if client is None:
        close(cid)
    return states


def test_same_commands_give_bit_identical_states() -> None:
    assert run_scripted(7) == run_scripted(7)


def test_a_used_client_rebuilt_gives_the_states_of_a_fresh_one() -> None:
    cid = create_world(SETTINGS)
    try:
        history = run_scripted(3, cid)  # a crash and a teleport for the client to forget
        again = run_scripted(7, cid)
    finally:
        close(cid)
    assert again == run_scripted(7) != history
