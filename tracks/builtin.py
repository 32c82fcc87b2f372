"""Slipstream's own tracks, designed here from a handful of control points.

Each design is a closed control polygon smoothed by a periodic cubic B-spline
(curvature-continuous), scaled to its target length, resampled at an even
spacing and given borders offset along the normals by half the width. The
stored direction is counter-clockwise; ``Track.reversed()`` gives the other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracks.geometry import cumulative_length, signed_area
from tracks.track import Track, TrackError

SPACING = 0.2
"""Target distance between consecutive waypoints, metres."""

_DENSE_PER_SPAN = 64


@dataclass(frozen=True)
class TrackDesign:
    """A built-in track's recipe: control polygon (any scale), target length and width."""

    name: str
    display_name: str
    description: str
    control_points: tuple[tuple[float, float], ...]
    length: float
    width: float


def periodic_bspline(control: np.ndarray, per_span: int = _DENSE_PER_SPAN) -> np.ndarray:
    """Densely sample the closed uniform cubic B-spline of a control polygon (no repeat)."""
    ctrl = np.asarray(control, dtype=float)
    n = len(ctrl)
    t = np.arange(per_span) / per_span
    basis = (
        np.stack(
            [(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3],
            axis=1,
        )
        / 6.0
    )
    idx = (np.arange(n)[:, None] + np.arange(4)[None, :]) % n
    spans = np.einsum("tk,skd->std", basis, ctrl[idx])
    return spans.reshape(-1, 2)


def resample_closed(points: np.ndarray, spacing: float) -> np.ndarray:
    """Resample a closed curve (no repeated end point) at an even arc-length spacing."""
    ring = np.vstack([points, points[:1]])
    cum = cumulative_length(ring)
    count = max(round(cum[-1] / spacing), 8)
    s = np.linspace(0.0, cum[-1], count, endpoint=False)
    return np.stack([np.interp(s, cum, ring[:, 0]), np.interp(s, cum, ring[:, 1])], axis=1)


def closed_normals(points: np.ndarray) -> np.ndarray:
    """Unit left normals of a closed curve from central differences."""
    tangent = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)


def closed_curvature(points: np.ndarray) -> np.ndarray:
    """Signed curvature (1/m, positive turning left) of a closed curve at each point."""
    a, b, c = np.roll(points, 1, axis=0), points, np.roll(points, -1, axis=0)
    ab, bc, ca = b - a, c - b, a - c
    cross = ab[:, 0] * bc[:, 1] - ab[:, 1] * bc[:, 0]
    denom = np.linalg.norm(ab, axis=1) * np.linalg.norm(bc, axis=1) * np.linalg.norm(ca, axis=1)
    return 2.0 * cross / np.maximum(denom, 1e-12)


def centerline(design: TrackDesign, spacing: float = SPACING) -> np.ndarray:
    """The design's counter-clockwise centre line at its target length (no repeated point)."""
    ctrl = np.asarray(design.control_points, dtype=float)
    if signed_area(ctrl) < 0:
        ctrl = ctrl[::-1]
    dense = periodic_bspline(ctrl)
    dense_length = cumulative_length(np.vstack([dense, dense[:1]]))[-1]
    dense = (dense - dense.mean(axis=0)) * (design.length / dense_length)
    return resample_closed(dense, spacing)


def build(design: TrackDesign, spacing: float = SPACING) -> Track:
    """Turn a design into a validated counter-clockwise :class:`Track`."""
    center = centerline(design, spacing)
    radius = 1.0 / np.max(np.abs(closed_curvature(center)))
    if radius <= design.width / 2:
        raise TrackError(
            f"{design.name}: tightest radius {radius:.2f} m is below half the width "
            f"({design.width / 2:.2f} m)"
        )
    offset = closed_normals(center) * (design.width / 2)
    ring = [np.vstack([a, a[:1]]) for a in (center, center + offset, center - offset)]
    return Track.from_arrays(
        design.name,
        *ring,
        display_name=design.display_name,
        is_loop=True,
        description=design.description,
    )


DESIGNS: tuple[TrackDesign, ...] = (
    TrackDesign(
        name="beginner_loop",
        display_name="Beginner Loop",
        description="A friendly 17.6 m loop: long gentle bends and two tighter corners.",
        control_points=(
            (0, 0), (4, 0), (8, 0), (11, 0), (12.5, 1.5), (12, 4), (10, 5), (8, 4.2),
            (6.5, 4.5), (5.5, 6.5), (3.5, 7.5), (1, 7), (-0.5, 5), (-1, 2.5),
        ),
        length=17.6,
        width=0.76,
    ),
    TrackDesign(
        name="slipstream_speedway",
        display_name="Slipstream Speedway",
        description="A wide, fast 23 m tri-oval: flat-out straights and sweeping bends.",
        control_points=(
            (0, 0), (5, 0), (10, 0), (13, 0.5), (14.5, 3), (13, 6), (10, 7.5), (7, 6.8),
            (4, 7.5), (1, 6.5), (-1.5, 3.5), (-1.5, 1),
        ),
        length=23.0,
        width=1.07,
    ),
    TrackDesign(
        name="hairpin_hollow",
        display_name="Hairpin Hollow",
        description="A technical 34 m circuit with a tight hairpin and a quick S-bend.",
        control_points=(
            (0.6, 0), (3, 0), (6, 0), (8, 0), (9.6, 0.4), (10.3, 2), (10.3, 3.2), (8.5, 4.4),
            (8.5, 5.6), (8.7, 6.6), (8.1, 7.3), (7, 7.3), (5.5, 7.3), (4.2, 7.3), (3.1, 7.6),
            (2.7, 8.6), (3.1, 9.6), (4.2, 9.9),
            (5.5, 9.9), (7.5, 9.9), (9, 10.3), (9.3, 11.6), (8, 12.5), (5, 12.5), (1, 12.5),
            (-0.4, 11.7), (-0.9, 9), (-0.9, 5), (-0.9, 2.5), (-0.6, 0.7),
        ),
        length=34.0,
        width=0.91,
    ),
    TrackDesign(
        name="grand_tour",
        display_name="Grand Tour",
        description="A 55 m endurance circuit mixing long straights, sweepers and a chicane.",
        control_points=(
            (0, 0), (6, 0), (12, 0), (18, 0), (21, 1), (22, 4), (20, 6), (17, 6), (15, 8),
            (16, 11), (19, 12), (21, 14), (20, 17), (16, 18), (12, 17), (10, 14), (8, 15.5),
            (6, 17), (3, 17), (1, 15), (2, 12), (0, 10), (-2.5, 8), (-3, 4), (-2, 1),
        ),
        length=55.0,
        width=1.07,
    ),
)  # fmt: skip

BUILTIN_DESIGNS: dict[str, TrackDesign] = {d.name: d for d in DESIGNS}
