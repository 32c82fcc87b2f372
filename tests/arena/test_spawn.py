"""Starting and respawn places, and the lane swap bots and respawns share."""

from __future__ import annotations

import pytest

from arena.spawn import other_lane, place, respawn_place
from tracks.catalog import get_track


def test_other_lane_swaps_inner_and_outer() -> None:
    assert other_lane("inner") == "outer"
    assert other_lane("outer") == "inner"


def test_respawn_after_an_obstacle_is_behind_it_in_the_other_lane() -> None:
    track = get_track("beginner_loop")
    spot = respawn_place(track, 3.0, 0.0, obstacle=(5.0, "inner"))
    expected = place(track, 4.0, "outer")
    assert (spot.arc, spot.offset) == pytest.approx((expected.arc, expected.offset))
