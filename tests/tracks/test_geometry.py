"""Projection, progress and road-polygon invariants of ``Track``."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import ellipse_track
from tracks.track import Track

TRACK = ellipse_track()
REVERSED = TRACK.reversed()
fractions = st.floats(min_value=0.0, max_value=0.999, allow_nan=False)


def _normal(heading: np.ndarray) -> np.ndarray:
    return np.stack([-np.sin(heading), np.cos(heading)], axis=-1)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 99_999), min_size=2, max_size=20, unique=True))
def test_progress_increases_along_the_centre_line(steps: list[int]) -> None:
    s = np.sort(np.array(steps)) * 1e-5 * TRACK.length  # points at least 0.1 mm apart
    pos, _ = TRACK.pose_at(s)
    progress = TRACK.project(pos).progress
    assert np.all(np.diff(progress) > 0)
    np.testing.assert_allclose(progress, 100 * s / TRACK.length, atol=1e-6)


@settings(max_examples=200, deadline=None)
@given(fractions, st.integers(min_value=-3, max_value=3))
def test_progress_wraps_at_100(frac: float, laps: int) -> None:
    s = frac * TRACK.length
    pos, _ = TRACK.pose_at(s + laps * TRACK.length)
    progress = TRACK.project(pos).progress[0]
    assert 0.0 <= progress < 100.0
    assert progress == pytest.approx(100 * frac, abs=1e-6)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=0.001, max_value=0.999), st.floats(min_value=-0.3, max_value=0.3))
def test_reversal_maps_progress_to_100_minus_progress(frac: float, offset: float) -> None:
    s = frac * TRACK.length
    pos, heading = TRACK.pose_at(s)
    point = pos + offset * _normal(heading)
    forward = TRACK.project(point)
    backward = REVERSED.project(point)
    assert backward.progress[0] == pytest.approx(100.0 - forward.progress[0], abs=1e-6)
    assert backward.offset[0] == pytest.approx(-forward.offset[0], abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(fractions, st.floats(min_value=-0.37, max_value=0.37).filter(lambda d: abs(d) > 1e-6))
def test_lateral_offset_sign_matches_side(frac: float, offset: float) -> None:
    s = frac * TRACK.length
    pos, heading = TRACK.pose_at(s)
    point = pos + offset * _normal(heading)
    proj = TRACK.project(point)
    assert bool(proj.is_left_of_center[0]) == (offset > 0)
    assert proj.distance_from_center[0] == pytest.approx(abs(offset), rel=0.05, abs=1e-6)
    assert bool(TRACK.contains(point)[0])


@settings(max_examples=200, deadline=None)
@given(fractions, st.integers(min_value=-2, max_value=2))
def test_heading_at_points_along_the_road_as_pose_at_does(frac: float, laps: int) -> None:
    for track in (TRACK, REVERSED):
        s = (frac + laps) * track.length
        heading = track.heading_at(s)
        assert heading == track.pose_at(s)[1]  # the same number, without the position
        ahead = track.pose_at(s + 1e-4)[0] - track.pose_at(s)[0]
        assert np.cos(heading - np.arctan2(ahead[1], ahead[0])) > 0.99
    arcs = np.linspace(-1.0, 2.5 * TRACK.length, 40)
    np.testing.assert_array_equal(TRACK.heading_at(arcs), TRACK.pose_at(arcs)[1])


def test_points_beyond_the_borders_are_off_the_road() -> None:
    s = np.linspace(0, TRACK.length, 50, endpoint=False)
    pos, heading = TRACK.pose_at(s)
    n = _normal(heading)
    assert TRACK.contains(pos).all()
    assert not TRACK.contains(pos + 0.45 * n).any()
    assert not TRACK.contains(pos - 0.45 * n).any()
    assert not TRACK.contains(np.zeros((1, 2))).any()


def test_closest_waypoints_hold_the_projection() -> None:
    pos, _ = TRACK.pose_at(np.array([0.0, 1.0, TRACK.length - 0.01]))
    proj = TRACK.project(pos)
    prev, nxt = proj.closest_waypoints.T
    np.testing.assert_array_equal(nxt, prev + 1)
    assert prev[0] == 0
    assert nxt[-1] == len(TRACK.waypoints) - 1
    for p, i in zip(pos, prev, strict=True):
        a, b = TRACK.waypoints[i], TRACK.waypoints[i + 1]
        t = np.dot(p - a, b - a) / np.dot(b - a, b - a)
        assert -1e-9 <= t <= 1 + 1e-9


def test_track_width_and_lanes() -> None:
    s = np.linspace(0, TRACK.length, 17)
    proj = TRACK.project(TRACK.pose_at(s)[0])
    np.testing.assert_allclose(proj.track_width, 0.76, atol=1e-9)
    inner, _ = TRACK.pose_at(s, "inner")
    outer, _ = TRACK.pose_at(s, "outer")
    np.testing.assert_allclose(TRACK.project(inner).offset, 0.19, atol=1e-3)  # ccw: inner = left
    np.testing.assert_allclose(TRACK.project(outer).offset, -0.19, atol=1e-3)
    cw_inner, _ = REVERSED.pose_at(s, "inner")
    assert (REVERSED.project(cw_inner).offset < 0).all()  # cw: inner = right


def test_direction_and_reversal_twice_is_identity() -> None:
    assert TRACK.direction == "ccw"
    assert REVERSED.direction == "cw"
    twice = REVERSED.reversed()
    np.testing.assert_array_equal(twice.waypoints, TRACK.waypoints)
    np.testing.assert_array_equal(twice.left, TRACK.left)
    assert TRACK.with_direction("cw").direction == "cw"
    assert TRACK.with_direction("ccw") is TRACK


def test_track_arrays_are_immutable() -> None:
    with pytest.raises(ValueError):
        TRACK.waypoints[0, 0] = 1.0


@settings(max_examples=200, deadline=None)
@given(fractions, fractions)
def test_arc_delta_on_a_loop_is_the_short_way_round(start: float, end: float) -> None:
    length = TRACK.length
    delta = TRACK.arc_delta(start * length, end * length)
    assert isinstance(delta, float)
    assert -length / 2 <= delta < length / 2
    turns = (end * length - start * length - delta) / length  # whole laps apart
    assert turns == pytest.approx(round(turns), abs=1e-9)


def test_arc_delta_crosses_the_start_line_on_loops_only() -> None:
    length = TRACK.length
    assert TRACK.arc_delta(length - 0.5, 0.5) == pytest.approx(1.0)
    assert TRACK.arc_delta(0.5, length - 0.5) == pytest.approx(-1.0)
    assert TRACK.arc_delta(2.0, 3.0) == pytest.approx(1.0)
    centre, left, right = ([[0.0, y], [10.0, y]] for y in (0.0, 0.4, -0.4))
    straight = Track.from_arrays("straight", centre, left, right)
    assert not straight.is_loop
    assert straight.arc_delta(9.5, 0.5) == -9.0
    assert straight.arc_delta(0.5, 9.5) == 9.0


def test_arc_delta_is_vectorised() -> None:
    length = TRACK.length
    starts = np.array([0.0, 1.0, length - 1.0])
    deltas = TRACK.arc_delta(starts, np.array([[0.5], [length - 0.5]]))
    assert isinstance(deltas, np.ndarray) and deltas.shape == (2, 3)
    expected = [[0.5, -0.5, 1.5], [-0.5, -1.5, 0.5]]
    np.testing.assert_allclose(deltas, expected, atol=1e-9)
