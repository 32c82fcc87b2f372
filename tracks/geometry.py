"""Vectorised planar geometry on polylines: projection, point-in-polygon, intersections.

Every function takes many points at once as an ``(P, 2)`` array; the arena calls
these every control step for every car and wheel, so nothing here loops in Python
over points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EPS = 1e-12


@dataclass(frozen=True)
class PolylineProjection:
    """Closest points of many query points on one polyline.

    Attributes:
        segment: index ``i`` of the segment ``(vertices[i], vertices[i + 1])`` holding
            the closest point, shape ``(P,)``.
        fraction: position of the closest point along that segment in ``[0, 1]``.
        arc_length: distance along the polyline from ``vertices[0]`` to the closest point.
        offset: signed distance to the closest point, positive on the left of the
            polyline's direction of travel.
        distance: unsigned distance to the closest point (``abs(offset)``).
        closest: the closest points themselves, shape ``(P, 2)``.
    """

    segment: np.ndarray
    fraction: np.ndarray
    arc_length: np.ndarray
    offset: np.ndarray
    distance: np.ndarray
    closest: np.ndarray


def as_points(points: np.ndarray | list | tuple) -> np.ndarray:
    """Return ``points`` as a float ``(P, 2)`` array (a single point becomes ``(1, 2)``)."""
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"expected points of shape (P, 2), got {arr.shape}")
    return arr


def cumulative_length(vertices: np.ndarray) -> np.ndarray:
    """Arc length at each vertex of a polyline, starting at 0."""
    seg = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


@dataclass(frozen=True)
class Segments:
    """A polyline's segments ``(ax, ay) -> (ax + dx, ay + dy)``, precomputed for repeated
    projections as separate contiguous columns: a projection of a few points is then a
    handful of small array operations."""

    ax: np.ndarray
    ay: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    length2: np.ndarray
    safe_length2: np.ndarray  # length2, at least EPS (a repeated vertex's segment)
    cum_length: np.ndarray

    @classmethod
    def of(cls, vertices: np.ndarray, cum_length: np.ndarray | None = None) -> Segments:
        """The segments of the polyline through ``vertices`` (no wrap-around)."""
        d = vertices[1:] - vertices[:-1]
        if cum_length is None:
            cum_length = cumulative_length(vertices)
        columns = (vertices[:-1, 0], vertices[:-1, 1], d[:, 0], d[:, 1])
        ax, ay, dx, dy = (np.ascontiguousarray(c) for c in columns)
        length2 = dx * dx + dy * dy
        return cls(ax, ay, dx, dy, length2, np.maximum(length2, EPS), cum_length)


def project_onto_polyline(
    points: np.ndarray, vertices: np.ndarray, cum_length: np.ndarray | None = None
) -> PolylineProjection:
    """Project points onto the polyline through ``vertices`` (no wrap-around).

    Ties between equally close segments go to the lower segment index, so results are
    deterministic. Cost is ``O(P * S)`` in memory and time, with ``S`` segments.
    """
    return project_onto_segments(points, Segments.of(vertices, cum_length))


def project_onto_segments(points: np.ndarray, segments: Segments) -> PolylineProjection:
    """:func:`project_onto_polyline` with the polyline's segments computed beforehand."""
    pts = as_points(points)
    px, py = pts[:, 0:1], pts[:, 1:2]
    rx = px - segments.ax
    ry = py - segments.ay
    t = rx * segments.dx
    t += ry * segments.dy
    t /= segments.safe_length2
    np.maximum(t, 0.0, out=t)
    np.minimum(t, 1.0, out=t)
    rx -= t * segments.dx
    ry -= t * segments.dy
    rx *= rx
    ry *= ry
    dist2 = rx
    dist2 += ry
    seg = dist2.argmin(axis=1)
    rows = np.arange(len(pts))
    frac = t[rows, seg]
    seg_dx, seg_dy = segments.dx[seg], segments.dy[seg]
    closest = np.empty_like(pts)
    closest[:, 0] = segments.ax[seg] + frac * seg_dx
    closest[:, 1] = segments.ay[seg] + frac * seg_dy
    arc = segments.cum_length[seg] + frac * np.sqrt(segments.length2[seg])
    cross = seg_dx * (pts[:, 1] - closest[:, 1]) - seg_dy * (pts[:, 0] - closest[:, 0])
    distance = np.sqrt(dist2[rows, seg])
    offset = np.where(cross >= 0.0, distance, -distance)
    return PolylineProjection(seg, frac, arc, offset, distance, closest)


@dataclass(frozen=True)
class Edges:
    """The edges ``a -> b`` of one or more closed rings, precomputed for inside tests:
    each edge's start ``ax``, ``ay``, end height ``by``, run ``dx`` and non-zero rise
    ``rise`` (horizontal edges get ``EPS``; they never straddle a point's height)."""

    ax: np.ndarray
    ay: np.ndarray
    by: np.ndarray
    dx: np.ndarray
    rise: np.ndarray

    @classmethod
    def of_rings(cls, rings: list[np.ndarray]) -> Edges:
        """Every ring's edges, the closing edge (last vertex back to the first) included."""
        a = np.vstack(rings)
        b = np.vstack([np.roll(ring, -1, axis=0) for ring in rings])
        rise = b[:, 1] - a[:, 1]
        return cls(
            ax=np.ascontiguousarray(a[:, 0]),
            ay=np.ascontiguousarray(a[:, 1]),
            by=np.ascontiguousarray(b[:, 1]),
            dx=b[:, 0] - a[:, 0],
            rise=np.where(rise == 0.0, EPS, rise),
        )


def crossings(points: np.ndarray, ring: np.ndarray | Edges) -> np.ndarray:
    """Count how often a ray from each point towards +x crosses the closed ``ring``.

    ``ring`` is ``(M, 2)``; the edge from the last vertex back to the first is implied.
    :class:`Edges` of several rings count the crossings of all of them.
    Used for even-odd inside tests of polygons with holes.
    """
    edges = ring if isinstance(ring, Edges) else Edges.of_rings([ring])
    pts = as_points(points)
    px = pts[:, 0:1]
    py = pts[:, 1:2]
    straddles = (edges.ay > py) != (edges.by > py)
    x_at = py - edges.ay
    x_at *= edges.dx
    x_at /= edges.rise
    x_at += edges.ax
    straddles &= px < x_at
    return np.count_nonzero(straddles, axis=1)


def inside_rings(points: np.ndarray, rings: list[np.ndarray] | Edges) -> np.ndarray:
    """Even-odd inside test of points against the region bounded by several rings."""
    edges = rings if isinstance(rings, Edges) else Edges.of_rings(rings)
    return (crossings(points, edges) % 2) == 1


def segments_intersect(
    p1: np.ndarray, p2: np.ndarray, q1: np.ndarray, q2: np.ndarray
) -> np.ndarray:
    """Whether segments ``p1-p2`` and ``q1-q2`` cross or touch (broadcasting)."""

    def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        v = (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
            c[..., 0] - a[..., 0]
        )
        return np.sign(np.where(np.abs(v) < 1e-12, 0.0, v))

    o1 = orient(p1, p2, q1)
    o2 = orient(p1, p2, q2)
    o3 = orient(q1, q2, p1)
    o4 = orient(q1, q2, p2)
    crossing = (o1 * o2 <= 0) & (o3 * o4 <= 0)
    collinear = (o1 == 0) & (o2 == 0)
    overlap = np.ones_like(crossing)
    for k in (0, 1):
        lo_p = np.minimum(p1[..., k], p2[..., k])
        hi_p = np.maximum(p1[..., k], p2[..., k])
        lo_q = np.minimum(q1[..., k], q2[..., k])
        hi_q = np.maximum(q1[..., k], q2[..., k])
        overlap &= (lo_p <= hi_q) & (lo_q <= hi_p)
    return crossing & (~collinear | overlap)


SELF_INTERSECTION_BLOCK = 256  # segments checked at once: memory stays O(block x n), not O(n^2)


def first_self_intersection(vertices: np.ndarray, closed: bool) -> tuple[int, int] | None:
    """Return the first pair of non-adjacent segments of a polyline that cross, if any.

    "First" is the smallest ``i``, then the smallest ``j > i + 1``. Checked a block of rows
    at a time, so a long polyline costs time but never a quadratic array.
    """
    a = vertices[:-1]
    b = vertices[1:]
    n = len(a)
    for start in range(0, n, SELF_INTERSECTION_BLOCK):
        rows = np.arange(start, min(start + SELF_INTERSECTION_BLOCK, n))
        cols = np.arange(start + 2, n)
        if not len(cols):
            break
        hit = segments_intersect(a[rows, None], b[rows, None], a[None, cols], b[None, cols])
        hit &= cols[None, :] >= rows[:, None] + 2
        if closed:
            hit &= ~((rows[:, None] == 0) & (cols[None, :] == n - 1))
        if hit.any():
            r, c = np.unravel_index(int(np.argmax(hit)), hit.shape)
            return int(rows[r]), int(cols[c])
    return None


def signed_area(ring: np.ndarray) -> float:
    """Shoelace area of a ring: positive when its vertices run counter-clockwise."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
