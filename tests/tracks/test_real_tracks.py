"""Every real DeepRacer track file from ../shared loads, with the published lengths."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tracks.io import read_npy

pytestmark = pytest.mark.realdata

# Files whose centre-line length disagrees with the length the source table lists by
# more than 1%. Measured here: caecer_loop's file is 35.09 m but the table says 39.12 m
# (its width also differs, 1.29 vs 1.08 m: the table describes another revision), and
# thunder_hill_open's file is 40.91 m against 41.55 m (1.5%).
KNOWN_LENGTH_MISMATCHES = {"caecer_loop", "thunder_hill_open"}
OPEN_TRACKS = {"Straight_track"}


def published_lengths(folder: Path) -> dict[str, float]:
    """Track lengths from the source README table, keyed by file stem."""
    lengths = {}
    for line in (folder / "SOURCE_README.md").read_text().splitlines():
        cells = [c.strip() for c in line.split("|")]
        if len(cells) < 7 or ".npy" not in cells[4]:
            continue
        metres = float(cells[5].split()[0])
        for stem in re.findall(r"\[([\w\-]+)\.npy\]", cells[4]):
            lengths[stem] = metres
    return lengths


def test_all_real_tracks_load(shared_tracks: Path) -> None:
    files = sorted(shared_tracks.glob("*.npy"))
    assert len(files) >= 120
    lengths = published_lengths(shared_tracks)
    mismatched = set()
    for path in files:
        track = read_npy(path)
        assert track.is_loop == (path.stem not in OPEN_TRACKS), path.stem
        twice = track.reversed().reversed()
        np.testing.assert_array_equal(twice.waypoints, track.waypoints)
        np.testing.assert_array_equal(twice.left, track.left)
        if path.stem.endswith("_cw"):
            assert track.direction == "cw", path.stem
        if path.stem.endswith("_ccw"):
            assert track.direction == "ccw", path.stem
        if path.stem in lengths and abs(track.length / lengths[path.stem] - 1) > 0.01:
            mismatched.add(path.stem)
    assert mismatched == KNOWN_LENGTH_MISMATCHES


def test_reinvent_base_matches_the_beginner_figures(shared_tracks: Path) -> None:
    track = read_npy(shared_tracks / "reinvent_base.npy")
    assert track.length == pytest.approx(17.6, rel=0.01)
    assert track.width == pytest.approx(0.76, abs=0.01)
    assert track.direction == "ccw"
    start, _ = track.pose_at(0.0)
    assert track.point_inside_road(start[0] if start.ndim == 2 else start)
