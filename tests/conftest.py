"""Shared test fixtures: synthetic tracks and the location of the real DeepRacer data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracks.track import Track

SHARED_TRACKS = Path(__file__).resolve().parents[1].parent / "shared" / "deepracer-data" / "tracks"


def ellipse_track(
    a: float = 3.0, b: float = 2.0, width: float = 0.76, n: int = 120, name: str = "ellipse"
) -> Track:
    """A counter-clockwise elliptical loop (not a built-in; for geometry tests)."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    center = np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
    tangent = np.stack([-a * np.sin(t), b * np.cos(t)], axis=1)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    left = center + 0.5 * width * normal
    right = center - 0.5 * width * normal
    close = lambda arr: np.vstack([arr, arr[:1]])  # noqa: E731
    return Track.from_arrays(name, close(center), close(left), close(right))


@pytest.fixture(scope="session")
def ellipse() -> Track:
    """A 3 m x 2 m elliptical loop, 0.76 m wide."""
    return ellipse_track()


@pytest.fixture(scope="session")
def shared_tracks() -> Path:
    """The real DeepRacer track folder (``../shared/deepracer-data/tracks`` beside the
    checkout): every ``realdata`` test reads it through this fixture, and skips, naming the
    folder it looked in, when it is absent."""
    if not SHARED_TRACKS.is_dir():
        pytest.skip(
            f"realdata: no DeepRacer track folder at {SHARED_TRACKS} "
            "(the tests read ../shared/deepracer-data beside the checkout)"
        )
    return SHARED_TRACKS
