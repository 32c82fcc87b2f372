"""The ``Track``: an immutable centre line with left and right borders."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Literal

import numpy as np

from tracks.geometry import (
    Edges,
    Segments,
    as_points,
    cumulative_length,
    first_self_intersection,
    inside_rings,
    project_onto_segments,
    signed_area,
)

Lane = Literal["center", "inner", "outer", "left", "right"]

MAX_TRACK_POINTS = 2_000
"""Most distinct points a track may have (a loop's repeated closing point is not counted).
DeepRacer's own tracks have 22 to 401; the self-crossing check costs time and memory
quadratic in points (2,000 points: about 0.7 s and 180 MiB a ring), so a larger track is
refused before it."""


class TrackError(ValueError):
    """A track's data is unusable; the message names the problem."""


@dataclass(frozen=True)
class Projection:
    """Where points lie relative to a track's centre line (all arrays of shape ``(P,)``).

    Attributes:
        arc_length: metres along the centre line from the start line.
        segment: index ``i`` of the centre-line segment ``(waypoints[i], waypoints[i+1])``.
        fraction: position along that segment, 0 to 1.
        offset: signed lateral offset, metres, positive left of the driving direction.
        distance_from_center: ``abs(offset)``, metres.
        track_width: local distance between the borders, metres.
        progress: ``100 * arc_length / length`` (0 to 100).
    """

    arc_length: np.ndarray
    segment: np.ndarray
    fraction: np.ndarray
    offset: np.ndarray
    distance_from_center: np.ndarray
    track_width: np.ndarray
    progress: np.ndarray

    @property
    def is_left_of_center(self) -> np.ndarray:
        """True where the point is left of the centre line, seen in the driving direction."""
        return self.offset > 0.0

    @property
    def closest_waypoints(self) -> np.ndarray:
        """DeepRacer's ``[prev, next]`` waypoint indices, shape ``(P, 2)``."""
        return np.stack([self.segment, self.segment + 1], axis=1)

    def rows(self, index: list[int] | np.ndarray) -> Projection:
        """The projections of the points at ``index``, in that order."""
        return Projection(*(getattr(self, name)[index] for name in _PROJECTION_FIELDS))


_PROJECTION_FIELDS = tuple(f.name for f in fields(Projection))


def _frozen(arr: np.ndarray) -> np.ndarray:
    out = np.array(arr, dtype=float, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Track:
    """A race track: centre line and borders in driving order.

    ``waypoints``, ``left`` and ``right`` are ``(N, 2)`` arrays in metres. For a loop the
    last point repeats the first (as in DeepRacer's files), so segment ``i`` always runs
    from point ``i`` to point ``i + 1``. ``left``/``right`` are seen in the driving
    direction. Build one with :meth:`from_arrays`, which validates and freezes the data.
    """

    name: str
    display_name: str
    waypoints: np.ndarray
    left: np.ndarray
    right: np.ndarray
    is_loop: bool
    description: str = ""
    _cum: np.ndarray = field(init=False, repr=False)
    _tangents: np.ndarray = field(init=False, repr=False)  # unit, one per segment
    _headings: np.ndarray = field(init=False, repr=False)  # radians, one per segment

    def __post_init__(self) -> None:
        for attr in ("waypoints", "left", "right"):
            object.__setattr__(self, attr, _frozen(getattr(self, attr)))
        object.__setattr__(self, "_cum", _frozen(cumulative_length(self.waypoints)))
        tangents = np.diff(self.waypoints, axis=0)
        tangents /= np.linalg.norm(tangents, axis=-1, keepdims=True)
        object.__setattr__(self, "_tangents", _frozen(tangents))
        headings = np.arctan2(tangents[:, 1], tangents[:, 0])
        object.__setattr__(self, "_headings", _frozen(headings))

    # ----------------------------------------------------------------- building
    @classmethod
    def from_arrays(
        cls,
        name: str,
        center: np.ndarray,
        left: np.ndarray,
        right: np.ndarray,
        *,
        display_name: str | None = None,
        is_loop: bool | None = None,
        description: str = "",
    ) -> Track:
        """Validate, clean and freeze track arrays.

        Consecutive repeated points are dropped; a loop is closed by repeating its first
        point. ``is_loop`` defaults to "first and last centre points coincide". Raises
        :class:`TrackError` naming the first problem found; arrays of more than
        :data:`MAX_TRACK_POINTS` points are refused before any quadratic check.
        """
        arrays = {"centre line": center, "left border": left, "right border": right}
        cleaned = {}
        for what, arr in arrays.items():
            try:
                a = np.asarray(arr, dtype=float)
            except (TypeError, ValueError) as exc:
                raise TrackError(f"{name}: {what} is not numeric ({exc})") from None
            if a.ndim != 2 or a.shape[1] != 2:
                raise TrackError(f"{name}: {what} must have shape (N, 2), got {a.shape}")
            if not np.all(np.isfinite(a)):
                bad = int(np.argwhere(~np.isfinite(a))[0][0])
                raise TrackError(f"{name}: {what} has a NaN or infinite value at point {bad}")
            if len(a) > MAX_TRACK_POINTS + 1:  # + a loop's closing point
                raise TrackError(
                    f"{name}: {what} has {len(a)} points; a track may have at most "
                    f"{MAX_TRACK_POINTS}"
                )
            cleaned[what] = a
        c, lft, rgt = cleaned.values()
        if not (len(c) == len(lft) == len(rgt)):
            raise TrackError(
                f"{name}: centre line and borders differ in length "
                f"({len(c)}, {len(lft)}, {len(rgt)})"
            )
        if is_loop is None:
            is_loop = bool(len(c) > 2 and np.allclose(c[0], c[-1], atol=1e-6))
        keep = np.ones(len(c), dtype=bool)
        keep[1:] = np.linalg.norm(np.diff(c, axis=0), axis=1) > 1e-9
        c, lft, rgt = c[keep], lft[keep], rgt[keep]
        if is_loop:
            if np.allclose(c[0], c[-1], atol=1e-6):
                c, lft, rgt = c[:-1], lft[:-1], rgt[:-1]
            if len(c) < 3:
                raise TrackError(f"{name}: a loop needs at least 3 distinct points, got {len(c)}")
            c, lft, rgt = (np.vstack([a, a[:1]]) for a in (c, lft, rgt))
        elif len(c) < 2:
            raise TrackError(f"{name}: an open track needs at least 2 distinct points")
        widths = np.linalg.norm(lft - rgt, axis=1)
        if np.any(widths < 0.05):
            raise TrackError(
                f"{name}: track width below 5 cm at point {int(np.argmin(widths))} "
                f"({widths.min():.3f} m); are the border columns right?"
            )
        seg = np.diff(c, axis=0)
        side = seg[:, 0] * (lft[:-1, 1] - c[:-1, 1]) - seg[:, 1] * (lft[:-1, 0] - c[:-1, 0])
        if np.mean(side > 0) < 0.5:
            lft, rgt = rgt, lft
        for what, ring in (("centre line", c), ("left border", lft), ("right border", rgt)):
            hit = first_self_intersection(ring, closed=is_loop)
            if hit is not None:
                raise TrackError(
                    f"{name}: the {what} crosses itself (segments {hit[0]} and {hit[1]})"
                )
        return cls(
            name=name,
            display_name=display_name or name,
            waypoints=c,
            left=lft,
            right=rgt,
            is_loop=is_loop,
            description=description,
        )

    # --------------------------------------------------------------- properties
    @cached_property
    def length(self) -> float:
        """Centre-line length in metres (read every step for every car: computed once)."""
        return float(self._cum[-1])

    @property
    def cumulative_length(self) -> np.ndarray:
        """Arc length at each waypoint."""
        return self._cum

    @cached_property
    def widths(self) -> np.ndarray:
        """Distance between the borders at each waypoint."""
        return _frozen(np.linalg.norm(self.left - self.right, axis=1))

    @cached_property
    def left_half_widths(self) -> np.ndarray:
        """Distance from the centre line to the left border at each waypoint."""
        return _frozen(np.linalg.norm(self.left - self.waypoints, axis=1))

    @cached_property
    def right_half_widths(self) -> np.ndarray:
        """Distance from the centre line to the right border at each waypoint."""
        return _frozen(np.linalg.norm(self.right - self.waypoints, axis=1))

    @property
    def width(self) -> float:
        """Median track width in metres (the figure people quote)."""
        return float(np.median(self.widths))

    @property
    def direction(self) -> Literal["ccw", "cw"]:
        """``ccw`` when the centre line runs counter-clockwise (open tracks: ``ccw``)."""
        if not self.is_loop:
            return "ccw"
        return "ccw" if signed_area(self.waypoints[:-1]) > 0 else "cw"

    @property
    def inner(self) -> np.ndarray:
        """Inner border (towards the loop's inside; left on open tracks)."""
        return self.left if self.direction == "ccw" else self.right

    @property
    def outer(self) -> np.ndarray:
        """Outer border (away from the loop's inside; right on open tracks)."""
        return self.right if self.direction == "ccw" else self.left

    @cached_property
    def road_rings(self) -> list[np.ndarray]:
        """Rings bounding the road for even-odd inside tests."""
        if self.is_loop:
            return [self.left[:-1], self.right[:-1]]
        return [np.vstack([self.left, self.right[::-1]])]

    @cached_property
    def _road_edges(self) -> Edges:
        return Edges.of_rings(self.road_rings)

    @cached_property
    def _segments(self) -> Segments:
        return Segments.of(self.waypoints, self._cum)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` over both borders."""
        pts = np.vstack([self.left, self.right])
        return (*pts.min(axis=0), *pts.max(axis=0))

    # ------------------------------------------------------------------ queries
    def project(self, points: np.ndarray) -> Projection:
        """Project points onto the centre line (vectorised over ``(P, 2)`` points)."""
        proj = project_onto_segments(points, self._segments)
        i, f = proj.segment, proj.fraction
        width = self.widths[i] * (1.0 - f) + self.widths[i + 1] * f
        arc = np.mod(proj.arc_length, self.length) if self.is_loop else proj.arc_length
        return Projection(
            arc_length=arc,
            segment=i,
            fraction=f,
            offset=proj.offset,
            distance_from_center=proj.distance,
            track_width=width,
            progress=100.0 * arc / self.length,
        )

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether each point lies on the road (inside the polygon between the borders)."""
        return inside_rings(points, self._road_edges)

    def wrap_arc_length(self, s: np.ndarray | float) -> np.ndarray:
        """Map arc lengths into ``[0, length)`` on loops, clip to ``[0, length]`` otherwise."""
        s = np.asarray(s, dtype=float)
        return np.mod(s, self.length) if self.is_loop else np.clip(s, 0.0, self.length)

    def arc_delta(self, start: np.ndarray | float, end: np.ndarray | float) -> np.ndarray | float:
        """Signed arc length from ``start`` to ``end`` (positive: ``end`` is ahead).

        On a loop the gap is taken the short way round, across the start line if need
        be, in ``[-length / 2, length / 2)``; on an open track it is ``end - start``.
        Vectorised: arrays broadcast and give an array; two scalars give a float.
        """
        # Two floats (the rules' per-car case) stay Python floats: no numpy call per car.
        scalars = type(start) is float and type(end) is float
        delta = end - start if scalars else np.subtract(end, start, dtype=float)
        if self.is_loop:
            half = 0.5 * self.length
            delta = (delta + half) % self.length - half  # np.mod on arrays
        if scalars:
            return delta
        return float(delta) if delta.ndim == 0 else delta

    def _locate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = self.wrap_arc_length(s)
        seg = np.clip(np.searchsorted(self._cum, s, side="right") - 1, 0, len(self._cum) - 2)
        seg_len = np.maximum(self._cum[seg + 1] - self._cum[seg], 1e-12)
        return seg, (s - self._cum[seg]) / seg_len

    def lane_offset(self, s: np.ndarray | float, lane: Lane | float = "center") -> np.ndarray:
        """Signed lateral offset (left positive) of a lane's centre at arc length ``s``.

        ``inner``/``outer`` lane centres are midway between centre line and that border,
        as in DeepRacer; a float is taken as an offset in metres.
        """
        seg, f = self._locate(np.asarray(s, dtype=float))
        if not isinstance(lane, str):
            return np.full(np.shape(seg), float(lane))
        if lane == "center":
            return np.zeros(np.shape(seg))
        if lane in ("inner", "outer"):
            lane = "left" if (lane == "inner") == (self.direction == "ccw") else "right"
        if lane == "left":
            hw = self.left_half_widths
            return 0.5 * (hw[seg] * (1 - f) + hw[seg + 1] * f)
        if lane == "right":
            hw = self.right_half_widths
            return -0.5 * (hw[seg] * (1 - f) + hw[seg + 1] * f)
        raise ValueError(f"unknown lane {lane!r}; use center, inner, outer, left, right or metres")

    def pose_at(
        self, s: np.ndarray | float, lane: Lane | float = "center"
    ) -> tuple[np.ndarray, np.ndarray]:
        """Position ``(..., 2)`` and heading (radians) at arc length ``s`` on a lane."""
        s_arr = np.asarray(s, dtype=float)
        seg, f = self._locate(s_arr)
        a, b = self.waypoints[seg], self.waypoints[seg + 1]
        tangent = self._tangents[seg]
        normal = np.stack([-tangent[..., 1], tangent[..., 0]], axis=-1)
        pos = a + f[..., None] * (b - a) + self.lane_offset(s_arr, lane)[..., None] * normal
        return pos, self._headings[seg]

    def heading_at(self, s: np.ndarray | float) -> np.ndarray:
        """Heading (radians) at arc length ``s``: :meth:`pose_at`'s, without the position."""
        seg, _ = self._locate(np.asarray(s, dtype=float))
        return self._headings[seg]

    def reversed(self) -> Track:
        """The same road driven the other way; a loop keeps its start line and its name."""
        return Track(
            name=self.name,
            display_name=self.display_name,
            waypoints=self.waypoints[::-1],
            left=self.right[::-1],
            right=self.left[::-1],
            is_loop=self.is_loop,
            description=self.description,
        )

    def with_direction(self, direction: Literal["ccw", "cw"]) -> Track:
        """This track driven ``ccw`` or ``cw`` (loops only; open tracks are returned as is)."""
        if direction not in ("ccw", "cw"):
            raise ValueError(f"direction must be 'ccw' or 'cw', got {direction!r}")
        if not self.is_loop or self.direction == direction:
            return self
        return self.reversed()

    def point_inside_road(self, point: np.ndarray | tuple[float, float]) -> bool:
        """Convenience scalar form of :meth:`contains`."""
        return bool(self.contains(as_points(point))[0])

    def __repr__(self) -> str:
        kind = "loop" if self.is_loop else "open"
        return (
            f"Track({self.name!r}, {kind}, {self.direction}, length={self.length:.2f} m, "
            f"width={self.width:.2f} m, {len(self.waypoints)} waypoints)"
        )
