"""The built-in tracks: valid, original designs with the promised sizes, both directions."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tracks.builtin import BUILTIN_DESIGNS, closed_curvature
from tracks.catalog import builtin_names, get_track

# name -> (min length, max length, width)
EXPECTED = {
    "beginner_loop": (17.0, 18.0, 0.76),
    "slipstream_speedway": (22.0, 24.0, 1.07),
    "hairpin_hollow": (25.0, 40.0, 0.91),
    "grand_tour": (50.0, 60.0, 1.07),
}
NAMES = builtin_names()


def test_catalogue_has_the_required_tracks():
    assert set(EXPECTED) <= set(NAMES)
    assert len(NAMES) >= 4


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("direction", ["ccw", "cw"])
def test_loads_in_both_directions_with_promised_size(name, direction):
    track = get_track(name, direction)
    lo, hi, width = EXPECTED[name]
    assert track.direction == direction
    assert track.is_loop
    assert lo <= track.length <= hi
    assert track.width == pytest.approx(width, abs=1e-6)
    assert np.allclose(track.widths, width, atol=1e-6)
    spacing = np.diff(track.cumulative_length)
    assert spacing.min() >= 0.15
    assert spacing.max() <= 0.25


@pytest.mark.parametrize("name", NAMES)
def test_stored_default_is_counter_clockwise_and_named(name):
    track = get_track(name)
    assert track.direction == "ccw"
    assert re.fullmatch(r"[a-z][a-z0-9_]*", track.name)
    assert track.display_name and track.display_name != track.name
    assert track.description and "\n" not in track.description
    assert track.reversed().length == pytest.approx(track.length)


@pytest.mark.parametrize("name", NAMES)
def test_corners_wider_than_half_the_road(name):
    track = get_track(name)
    radius = 1.0 / np.abs(closed_curvature(track.waypoints[:-1])).max()
    assert radius > BUILTIN_DESIGNS[name].width / 2 * 1.05


@pytest.mark.parametrize("name", NAMES)
def test_separate_parts_of_the_road_never_touch(name):
    track = get_track(name)
    c, s = track.waypoints[:-1], track.cumulative_length[:-1]
    apart = np.abs(s[:, None] - s[None, :])
    apart = np.minimum(apart, track.length - apart)
    dist = np.linalg.norm(c[:, None] - c[None, :], axis=2)
    # points more than 3 m apart along the road keep a verge between their roads
    assert dist[apart > 3.0].min() > track.width + 0.3


@settings(max_examples=40, deadline=None)
@given(
    name=st.sampled_from(NAMES),
    s=st.floats(0.0, 1.0, exclude_max=True),
    lane=st.floats(-0.9, 0.9),
)
def test_points_across_the_road_are_on_it(name, s, lane):
    track = get_track(name)
    pos, _ = track.pose_at(np.array([s * track.length]), lane * track.width / 2)
    assert track.contains(pos)[0]
    assert track.project(pos).distance_from_center[0] <= track.width / 2
