"""Reading and writing track files: DeepRacer ``.npy`` and Slipstream's JSON/YAML.

Every reader either returns a complete, validated :class:`~tracks.track.Track` or
raises :class:`TrackFileError` with one message naming the file and the problem. Files
are bounded before they are parsed: at most :data:`MAX_FILE_BYTES` bytes, and a ``.npy``
header must describe an array that fits in the file and in
:data:`~tracks.track.MAX_TRACK_POINTS` rows before any array is allocated.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from tracks.track import MAX_TRACK_POINTS, Track, TrackError

FORMAT_NAME = "slipstream-track"
FORMAT_VERSION = 1
MAX_FILE_BYTES = 2 * 1024 * 1024
"""Largest track file read (a 2,000-point track is about 100 KB as .npy, 300 KB as JSON)."""
SUFFIXES = (".npy", ".json", ".yaml", ".yml")
_NPY_MAX_HEADER_BYTES = 10_000


class TrackFileError(TrackError):
    """A track file could not be loaded; the message names the file and the problem.

    ``problem`` is the message without the file's path, for showing to people who
    should not learn where the file lives (a web client of the league).
    """

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{path}: {problem}")


def _check_file(path: Path) -> None:
    if not path.exists():
        raise TrackFileError(path, "no such file")
    if not path.is_file():
        raise TrackFileError(path, "not a file")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise TrackFileError(path, f"{size} bytes is larger than the {MAX_FILE_BYTES} byte limit")


def track_from_deepracer_array(
    data: np.ndarray, name: str, display_name: str | None = None
) -> Track:
    """Build a track from DeepRacer's ``N x 6`` array (centre, inner, outer columns)."""
    arr = np.asarray(data)
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise TrackError(f"{name}: expected an N x 6 array (centre, inner, outer), got {arr.shape}")
    if arr.dtype.kind not in "fiu":
        raise TrackError(f"{name}: expected numbers, got dtype {arr.dtype}")
    if len(arr) < 3:
        raise TrackError(f"{name}: needs at least 3 points, got {len(arr)}")
    return Track.from_arrays(name, arr[:, 0:2], arr[:, 2:4], arr[:, 4:6], display_name=display_name)


def track_to_deepracer_array(track: Track) -> np.ndarray:
    """DeepRacer's ``N x 6`` layout: centre, inner border, outer border (loops closed)."""
    return np.hstack([track.waypoints, track.inner, track.outer])


def _npy_header(path: Path) -> tuple[tuple[int, ...], np.dtype, int]:
    """Shape, dtype and data offset a ``.npy`` header declares, read without loading data."""
    with path.open("rb") as handle:
        version = np.lib.format.read_magic(handle)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(
                handle, max_header_size=_NPY_MAX_HEADER_BYTES
            )
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(
                handle, max_header_size=_NPY_MAX_HEADER_BYTES
            )
        else:
            raise ValueError(f".npy format version {version} is not supported (use 1.0 or 2.0)")
        return tuple(shape), dtype, handle.tell()


def _check_npy_header(path: Path) -> None:
    """Refuse a header whose array is not plain numbers, too long, or larger than the file."""
    try:
        shape, dtype, offset = _npy_header(path)
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise TrackFileError(path, f"not a readable .npy file ({exc})") from None
    if dtype.hasobject:
        raise TrackFileError(path, "not a plain numeric .npy array (it holds Python objects)")
    if shape and shape[0] > MAX_TRACK_POINTS + 1:  # + a loop's closing point
        raise TrackFileError(
            path, f"the array has {shape[0]} rows; a track may have at most {MAX_TRACK_POINTS}"
        )
    needed = math.prod(shape) * dtype.itemsize
    present = path.stat().st_size - offset
    if needed > present:
        raise TrackFileError(
            path, f"the header declares {shape} {dtype} ({needed} bytes) but {present} follow"
        )


def read_npy(path: str | Path, name: str | None = None) -> Track:
    """Load a DeepRacer ``.npy`` track file (never unpickles; header checked before loading)."""
    path = Path(path)
    _check_file(path)
    _check_npy_header(path)
    try:
        arr = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise TrackFileError(path, f"not a plain numeric .npy array ({exc})") from None
    except (OSError, EOFError) as exc:
        raise TrackFileError(path, f"not a readable .npy file ({exc})") from None
    if not isinstance(arr, np.ndarray):
        raise TrackFileError(path, "not a single numpy array")
    try:
        return track_from_deepracer_array(arr, name or path.stem)
    except TrackError as exc:
        raise TrackFileError(path, str(exc)) from None


def write_npy(track: Track, path: str | Path) -> Path:
    """Write a track in DeepRacer's ``.npy`` layout."""
    path = Path(path)
    np.save(path, track_to_deepracer_array(track))
    return path


def track_to_dict(track: Track) -> dict[str, Any]:
    """Slipstream's readable track document (loops listed without the closing point)."""
    n = len(track.waypoints) - 1 if track.is_loop else len(track.waypoints)
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "name": track.name,
        "display_name": track.display_name,
        "description": track.description,
        "loop": track.is_loop,
        "centerline": track.waypoints[:n].tolist(),
        "left_border": track.left[:n].tolist(),
        "right_border": track.right[:n].tolist(),
    }


def track_from_dict(doc: Any, source: str = "track") -> Track:
    """Parse Slipstream's track document, raising :class:`TrackError` on bad input."""
    if not isinstance(doc, dict):
        raise TrackError(f"{source}: expected a mapping at the top level, got {type(doc).__name__}")
    if doc.get("format", FORMAT_NAME) != FORMAT_NAME:
        raise TrackError(f"{source}: format is {doc.get('format')!r}, expected {FORMAT_NAME!r}")
    version = doc.get("version", FORMAT_VERSION)
    if version != FORMAT_VERSION:
        raise TrackError(f"{source}: format version {version!r} is not supported (use 1)")
    missing = [k for k in ("name", "centerline", "left_border", "right_border") if k not in doc]
    if missing:
        raise TrackError(f"{source}: missing field(s) {', '.join(missing)}")
    name = doc["name"]
    if not isinstance(name, str) or not name.strip():
        raise TrackError(f"{source}: 'name' must be a non-empty string")
    loop = doc.get("loop", True)
    if not isinstance(loop, bool):
        raise TrackError(f"{source}: 'loop' must be true or false")
    arrays = []
    for key in ("centerline", "left_border", "right_border"):
        try:
            arr = np.asarray(doc[key], dtype=float)
        except (TypeError, ValueError):
            raise TrackError(f"{source}: '{key}' must be a list of [x, y] numbers") from None
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise TrackError(f"{source}: '{key}' must be a list of [x, y] pairs, got {arr.shape}")
        if len(arr) < 3:
            raise TrackError(f"{source}: '{key}' needs at least 3 points, got {len(arr)}")
        arrays.append(arr)
    if loop:
        arrays = [np.vstack([a, a[:1]]) for a in arrays]
    display = doc.get("display_name") or name
    description = doc.get("description") or ""
    if not isinstance(display, str) or not isinstance(description, str):
        raise TrackError(f"{source}: 'display_name' and 'description' must be strings")
    return Track.from_arrays(
        name, *arrays, display_name=display, is_loop=loop, description=description
    )


def read_document(path: str | Path) -> Track:
    """Load a Slipstream ``.json`` or ``.yaml`` track file."""
    path = Path(path)
    _check_file(path)
    try:
        text = path.read_text(encoding="utf-8")
        if path.suffix == ".json":
            doc = json.loads(text, parse_constant=lambda c: math.nan)
        else:
            doc = yaml.safe_load(text)
    except (UnicodeDecodeError, json.JSONDecodeError, yaml.YAMLError) as exc:
        raise TrackFileError(path, f"not valid {path.suffix[1:].upper()} ({exc})") from None
    try:
        return track_from_dict(doc, source=path.name)
    except TrackFileError:
        raise
    except TrackError as exc:
        raise TrackFileError(path, str(exc)) from None


def write_document(track: Track, path: str | Path) -> Path:
    """Write Slipstream's track document as JSON (``.json``) or YAML (``.yaml``/``.yml``)."""
    path = Path(path)
    doc = track_to_dict(track)
    if path.suffix in (".yaml", ".yml"):
        path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    else:
        path.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return path


def read_track(path: str | Path, name: str | None = None) -> Track:
    """Load any supported track file, chosen by suffix."""
    path = Path(path)
    _check_file(path)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        return read_npy(path, name)
    if suffix in (".json", ".yaml", ".yml"):
        track = read_document(path)
        if name:
            track = Track(
                name=name,
                display_name=track.display_name,
                waypoints=track.waypoints,
                left=track.left,
                right=track.right,
                is_loop=track.is_loop,
                description=track.description,
            )
        return track
    raise TrackFileError(path, f"unknown track file type {suffix!r}; use one of {SUFFIXES}")
