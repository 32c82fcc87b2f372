"""Racing line and speed profile: on the road, within the car's limits, faster than the centre."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tracks.catalog import builtin_names, get_track
from tracks.geometry import project_onto_polyline
from tracks.raceline import (
    CarLimits,
    centerline_profile,
    compute_racing_line,
    profile_path,
    solve_box_qp,
)
from tracks.track import Track

LIMITS = CarLimits()
CASES = [(name, "ccw") for name in builtin_names()] + [("hairpin_hollow", "cw")]


@pytest.fixture(scope="module")
def lines():
    return {case: compute_racing_line(get_track(*case)) for case in CASES}


def test_defaults_describe_the_one_eighteenth_car():
    """DeepRacer's car as measured (tests/arena/test_calibration.py keeps them so): its
    wheels' 100 rad/s on a 0.036 m radius, grip-limited drive and braking near 0.5 g,
    cornering under it (the wheels scrub), slower the tighter the circle."""
    assert LIMITS.max_speed == pytest.approx(100 * 0.036, rel=0.01)
    assert LIMITS.max_accel == pytest.approx(0.5 * 9.81, rel=0.05)
    assert LIMITS.max_brake == pytest.approx(0.5 * 9.81, rel=0.05)
    assert LIMITS.max_lateral_accel < 0.5 * 9.81
    rows = np.array(LIMITS.cornering)
    assert np.all(np.diff(rows[:, 0]) > 0) and np.all(np.diff(rows[:, 1]) < 0)
    assert LIMITS.car_width == 0.196
    assert LIMITS.clearance == pytest.approx(0.098 + LIMITS.safety_margin)


def test_corner_speed_is_the_lower_of_grip_and_the_envelope():
    limits = CarLimits(max_lateral_accel=4.0, cornering=((0.5, 2.0), (1.0, 1.0)))
    assert limits.corner_speed(0.0) == limits.max_speed
    assert limits.corner_speed(0.25) == pytest.approx(min(np.sqrt(4.0 / 0.25), 3.599))
    assert limits.corner_speed(0.75) == pytest.approx(1.5)  # between the rows
    assert limits.corner_speed(-0.75) == pytest.approx(1.5)  # either way round
    assert limits.corner_speed(3.0) == pytest.approx(1.0)  # past the tightest: its speed
    grip_only = CarLimits(max_lateral_accel=4.0, cornering=())
    assert grip_only.corner_speed(0.75) == pytest.approx(np.sqrt(4.0 / 0.75))


@pytest.mark.parametrize(
    "rows", [((1.0, 2.0), (0.5, 1.0)), ((0.5, 2.0), (0.5, 1.0)), ((0.5, -1.0),), ((0.5,),)]
)
def test_limits_reject_a_nonsense_envelope(rows):
    with pytest.raises(ValueError, match="cornering"):
        CarLimits(cornering=rows)


def test_the_effective_wheelbase_grows_with_speed():
    limits = CarLimits(turning_wheelbase=0.2, understeer_gradient=0.03)
    assert limits.wheelbase_at(0.0) == 0.2
    assert limits.wheelbase_at(2.0) == pytest.approx(0.2 + 0.03 * 4.0)


@pytest.mark.parametrize("field", ["max_speed", "max_accel", "car_width"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan")])
def test_limits_reject_nonsense(field, value):
    with pytest.raises(ValueError, match=field):
        CarLimits(**{field: value})


@pytest.mark.parametrize("case", CASES)
def test_line_stays_on_the_road_with_margin(lines, case):
    track, line = get_track(*case), lines[case]
    assert track.contains(line.points).all()
    for border in (track.left, track.right):
        gap = project_onto_polyline(line.points, border).distance
        assert gap.min() >= LIMITS.clearance - 1e-3


@pytest.mark.parametrize("case", CASES)
def test_lap_time_between_top_speed_bound_and_centre_line(lines, case):
    track, line = get_track(*case), lines[case]
    assert line.length / LIMITS.max_speed < line.lap_time
    assert line.lap_time < centerline_profile(track, LIMITS).lap_time
    assert line.track_name == track.name
    assert line.direction == track.direction


@pytest.mark.parametrize("case", CASES)
def test_speed_respects_top_speed_grip_and_drivetrain(lines, case):
    line = lines[case]
    v, k = line.speed, line.curvature
    assert len(v) == len(k) == len(line.points) == len(line.arc_length)
    assert v.max() <= LIMITS.max_speed + 1e-9
    assert np.all(v**2 * np.abs(k) <= LIMITS.max_lateral_accel * (1 + 1e-9))
    ds = np.diff(line.arc_length)
    dv2 = np.diff(v**2)
    assert np.all(dv2 <= 2 * LIMITS.max_accel * ds + 1e-9)
    assert np.all(-dv2 <= 2 * LIMITS.max_brake * ds + 1e-9)
    assert v[0] == pytest.approx(v[-1])  # a flying lap closes on itself
    assert np.allclose(line.points[0], line.points[-1])


def test_deterministic_on_a_long_track():
    track = get_track("grand_tour")
    lines = [compute_racing_line(track) for _ in range(2)]
    assert np.array_equal(lines[0].points, lines[1].points)
    assert lines[0].lap_time == lines[1].lap_time


def test_direction_changes_little(lines):
    ccw = lines[("hairpin_hollow", "ccw")]
    cw = lines[("hairpin_hollow", "cw")]
    assert cw.lap_time == pytest.approx(ccw.lap_time, rel=0.05)


def test_to_dict_is_json(lines):
    line = lines[("beginner_loop", "ccw")]
    doc = json.loads(json.dumps(line.to_dict()))
    assert doc["lap_time"] == pytest.approx(line.lap_time, abs=1e-3)
    assert len(doc["points"]) == len(doc["speed"]) == len(line.points)
    assert doc["limits"]["max_speed"] == LIMITS.max_speed
    assert [tuple(row) for row in doc["limits"]["cornering"]] == list(LIMITS.cornering)
    assert "points" not in line.to_dict(include_points=False)


def test_open_straight_starts_from_standstill():
    x = np.linspace(0.0, 10.0, 41)
    center = np.stack([x, np.zeros_like(x)], axis=1)
    track = Track.from_arrays("strip", center, center + [0, 0.4], center - [0, 0.4], is_loop=False)
    line = compute_racing_line(track)
    assert line.speed[0] == 0.0
    assert np.allclose(line.points[:, 1], 0.0, atol=1e-6)
    run_up = LIMITS.max_speed**2 / (2 * LIMITS.max_accel)
    expected = LIMITS.max_speed / LIMITS.max_accel + (10.0 - run_up) / LIMITS.max_speed
    assert line.lap_time == pytest.approx(expected, rel=1e-3)


def _ring(radius: float, width: float) -> Track:
    angle = np.linspace(0.0, 2 * np.pi, max(int(2 * np.pi * radius / 0.1), 16), endpoint=False)
    unit = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    center = radius * unit
    inner, outer = (radius - width / 2) * unit, (radius + width / 2) * unit
    ring = [np.vstack([a, a[:1]]) for a in (center, inner, outer)]
    return Track.from_arrays("ring", *ring)


@settings(max_examples=8, deadline=None)
@given(radius=st.floats(1.0, 4.0), width=st.floats(0.6, 1.2))
def test_ring_is_driven_at_the_grip_limit(radius, width):
    line = compute_racing_line(_ring(radius, width))
    radii = np.linalg.norm(line.points, axis=1)
    assert radii.min() >= radius - width / 2 + LIMITS.clearance - 1e-3
    assert radii.max() <= radius + width / 2 - LIMITS.clearance + 1e-3
    slowest = float(LIMITS.corner_speed(1.0 / radii.min()))
    assert line.lap_time <= line.length / slowest * 1.01


@settings(max_examples=8, deadline=None)
@given(
    a_lat=st.floats(1.0, 10.0),
    accel=st.floats(0.5, 6.0),
    brake=st.floats(0.5, 8.0),
    top=st.floats(0.5, 6.0),
)
def test_profile_obeys_any_limits(a_lat, accel, brake, top):
    limits = CarLimits(max_speed=top, max_lateral_accel=a_lat, max_accel=accel, max_brake=brake)
    line = profile_path(get_track("beginner_loop").waypoints, limits)
    assert line.speed.max() <= top + 1e-9
    assert np.all(line.speed**2 * np.abs(line.curvature) <= a_lat * (1 + 1e-9))
    assert line.lap_time >= line.length / top * (1 - 1e-12)  # equal at top speed all round


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 8))
def test_box_qp_meets_optimality_conditions(seed, n):
    rng = np.random.default_rng(seed)
    m = rng.normal(size=(n, n))
    hessian = m @ m.T + 0.1 * np.eye(n)
    gradient = rng.normal(size=n) * 3
    lower = -rng.uniform(0.1, 1.0, size=n)
    upper = rng.uniform(0.1, 1.0, size=n)
    x = solve_box_qp(hessian, gradient, lower, upper)
    assert np.all(x >= lower) and np.all(x <= upper)
    grad = hessian @ x + gradient
    # By convexity f(y) >= f(x) + grad.(y - x), so over the box no point beats x by
    # more than this certificate: x is optimal to within it.
    certificate = np.sum(np.maximum(grad, 0) * (x - lower) + np.maximum(-grad, 0) * (upper - x))
    assert certificate < 1e-6
