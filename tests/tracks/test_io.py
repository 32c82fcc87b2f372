"""Track file import/export: DeepRacer .npy quirks, the JSON/YAML format, and bad files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import ellipse_track
from tracks.io import (
    TrackFileError,
    read_track,
    track_from_deepracer_array,
    track_to_deepracer_array,
    write_document,
    write_npy,
)
from tracks.track import MAX_TRACK_POINTS

TRACK = ellipse_track()


def _save(tmp_path: Path, arr: np.ndarray, name: str = "t.npy") -> Path:
    path = tmp_path / name
    np.save(path, arr)
    return path


def test_npy_round_trip_keeps_geometry(tmp_path: Path) -> None:
    path = write_npy(TRACK, tmp_path / "ellipse.npy")
    back = read_track(path)
    np.testing.assert_array_equal(back.waypoints, TRACK.waypoints)
    np.testing.assert_array_equal(back.left, TRACK.left)
    assert back.is_loop and back.name == "ellipse"


@pytest.mark.parametrize("suffix", [".json", ".yaml"])
def test_document_round_trip_is_exact(tmp_path: Path, suffix: str) -> None:
    path = write_document(TRACK, tmp_path / f"ellipse{suffix}")
    back = read_track(path)
    np.testing.assert_array_equal(back.waypoints, TRACK.waypoints)
    np.testing.assert_array_equal(back.right, TRACK.right)
    assert (back.name, back.display_name, back.is_loop) == ("ellipse", "ellipse", True)


def test_repeated_points_are_dropped(tmp_path: Path) -> None:
    arr = track_to_deepracer_array(TRACK)
    doubled = np.vstack([arr[:10], arr[9:10], arr[9:10], arr[10:]])
    back = read_track(_save(tmp_path, doubled))
    assert len(back.waypoints) == len(TRACK.waypoints)
    assert back.length == pytest.approx(TRACK.length)


def test_clockwise_file_keeps_inner_border_inside(tmp_path: Path) -> None:
    cw = TRACK.reversed()
    arr = track_to_deepracer_array(cw)
    np.testing.assert_array_equal(arr[:, 2:4], cw.right)  # cw loop: inner = right side
    back = read_track(_save(tmp_path, arr))
    assert back.direction == "cw"
    np.testing.assert_array_equal(back.left, cw.left)


def test_open_track_loads_as_open(tmp_path: Path) -> None:
    x = np.linspace(0, 5, 20)
    arr = np.stack([x, 0 * x, x, 0 * x + 0.3, x, 0 * x - 0.3], axis=1)
    track = read_track(_save(tmp_path, arr))
    assert not track.is_loop
    assert track.length == pytest.approx(5.0)
    assert track.project(np.array([[2.5, 0.1]])).progress[0] == pytest.approx(50.0)


BAD_ARRAYS = {
    "wrong shape": (np.zeros((10, 4)), "N x 6"),
    "one dimension": (np.zeros(12), "N x 6"),
    "too few points": (np.array([[0, 0, 0, 1, 0, -1], [1, 0, 1, 1, 1, -1]], float), "at least 3"),
    "NaN": (None, "NaN"),
    "strings": (np.array([["a"] * 6] * 5), "numbers"),
}


@pytest.mark.parametrize("case", sorted(BAD_ARRAYS))
def test_bad_arrays_are_refused_with_a_reason(tmp_path: Path, case: str) -> None:
    arr, reason = BAD_ARRAYS[case]
    if arr is None:
        arr = track_to_deepracer_array(TRACK).copy()
        arr[5, 3] = np.nan
    with pytest.raises(TrackFileError, match=reason) as err:
        read_track(_save(tmp_path, arr))
    assert "t.npy" in str(err.value)


def test_self_intersecting_border_is_refused(tmp_path: Path) -> None:
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    center = np.stack([3 * np.sin(t), 1.5 * np.sin(2 * t)], axis=1)  # a figure eight
    arr = np.hstack([center, center + [0, 0.3], center - [0, 0.3]])
    arr = np.vstack([arr, arr[:1]])
    with pytest.raises(TrackFileError, match="crosses itself"):
        read_track(_save(tmp_path, arr))


def test_not_a_file_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TrackFileError, match="not a file"):
        read_track(tmp_path)
    with pytest.raises(TrackFileError, match="no such file"):
        read_track(tmp_path / "missing.npy")


def test_garbage_and_pickled_npy_are_refused(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.npy"
    garbage.write_bytes(b"\x93NUMPY this is not really numpy" * 3)
    with pytest.raises(TrackFileError, match=r"garbage\.npy"):
        read_track(garbage)
    pickled = tmp_path / "pickled.npy"
    np.save(pickled, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(TrackFileError, match="plain numeric"):
        read_track(pickled)


@pytest.mark.parametrize(
    ("doc", "reason"),
    [
        ([1, 2, 3], "mapping"),
        ({"name": "x"}, "missing field"),
        ({"name": "x", "centerline": "abc", "left_border": [], "right_border": []}, "centerline"),
        (
            {"name": "x", "version": 7, "centerline": [], "left_border": [], "right_border": []},
            "version",
        ),
        ({"name": "", "centerline": [], "left_border": [], "right_border": []}, "name"),
    ],
)
def test_bad_documents_are_refused(tmp_path: Path, doc: object, reason: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(TrackFileError, match=reason):
        read_track(path)


def test_invalid_json_and_unknown_suffix(tmp_path: Path) -> None:
    path = tmp_path / "broken.json"
    path.write_text("{not json")
    with pytest.raises(TrackFileError, match="not valid JSON"):
        read_track(path)
    other = tmp_path / "track.csv"
    other.write_text("1,2")
    with pytest.raises(TrackFileError, match="unknown track file type"):
        read_track(other)


def _npy_claiming(shape: tuple[int, ...], total_bytes: int) -> bytes:
    """A .npy file of ``total_bytes`` whose header claims a float64 array of ``shape``."""
    header = f"{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}"
    header += " " * (118 - len(header) - 1) + "\n"
    data = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode()
    return data + bytes(total_bytes - len(data))


def test_npy_header_claiming_a_huge_array_is_refused_before_allocating(tmp_path: Path) -> None:
    """608 bytes claiming (2e9, 6) floats (89 GiB): a track-file error, never an allocation."""
    bomb = tmp_path / "bomb.npy"
    bomb.write_bytes(_npy_claiming((2_000_000_000, 6), 608))
    assert bomb.stat().st_size == 608
    with pytest.raises(TrackFileError, match="at most 2000") as err:
        read_track(bomb)
    assert "bomb.npy" in str(err.value)
    short = tmp_path / "short.npy"
    short.write_bytes(_npy_claiming((1_500, 6), 608))  # rows within the cap, data missing
    with pytest.raises(TrackFileError, match="declares"):
        read_track(short)


def _circle(points: int) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, points, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t)], axis=1)
    arr = np.hstack([5 * ring, 4.6 * ring, 5.4 * ring])
    return np.vstack([arr, arr[:1]])


@pytest.mark.parametrize("suffix", [".npy", ".json"])
def test_tracks_over_the_point_cap_are_refused(tmp_path: Path, suffix: str) -> None:
    """A clean but long track is refused with the cap named, before the quadratic check."""
    arr = _circle(MAX_TRACK_POINTS + 500)
    path = _save(tmp_path, arr, "long.npy")
    if suffix == ".json":
        doc = {
            "name": "long",
            "centerline": arr[:-1, 0:2].tolist(),
            "left_border": arr[:-1, 2:4].tolist(),
            "right_border": arr[:-1, 4:6].tolist(),
        }
        path = tmp_path / "long.json"
        path.write_text(json.dumps(doc))
    with pytest.raises(TrackFileError, match=f"at most {MAX_TRACK_POINTS}"):
        read_track(path)
    within = track_from_deepracer_array(_circle(MAX_TRACK_POINTS), "within")
    assert len(within.waypoints) == MAX_TRACK_POINTS + 1  # the loop's closing point
