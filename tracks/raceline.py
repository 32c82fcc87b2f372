"""The racing line and its speed profile: the league's physical-limit lap time.

The line is a minimum-curvature path between the borders: lateral offsets from an
evenly resampled centre line minimise the summed squared bends (second differences
projected on the normals), each offset boxed so that half the car plus a safety
margin stays on the road. That box-constrained quadratic programme is solved with a
primal-dual interior-point method (dense numpy solves, a few hundred unknowns). The
speed profile then respects grip (``v <= sqrt(a_lat / |k|)``), top speed,
acceleration and braking.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from tracks.geometry import cumulative_length, project_onto_polyline
from tracks.track import Track

GRAVITY = 9.81
STEP = 0.15
"""Default spacing of the optimised points, metres (about half a DeepRacer waypoint gap)."""
CURVATURE_WINDOW = 1.0
"""Metres over which curvature is averaged: finer kinks (polyline borders) are artefacts."""


@dataclass(frozen=True)
class CarLimits:
    """What the 1/18 car can do (SI units), as ``arena.calibration`` measures it by driving it.

    ``max_speed`` is the speed the car settles at on full command; ``max_accel`` and
    ``max_brake`` the constant rates that cover the same distance as its launch and its
    braking; ``max_lateral_accel`` the highest lateral acceleration it holds on a steady
    circle. ``cornering`` is the measured envelope of steady circles, ``(curvature 1/m,
    speed m/s)`` rows by rising curvature: the fastest circle the car holds at least that
    tight. It caps the speed where grip alone does not: on tight circles, where the
    steering's lock and the scrub of the wheels (no differential) leave the car short of
    its grip. Empty, grip alone decides. The steering's effective wheelbase, that of a car
    without scrub that would steer the same circles (``tan(steer) / curvature``), grows
    with speed: ``turning_wheelbase + understeer_gradient * v^2``
    (:meth:`wheelbase_at`). ``steering_time_constant`` is the lag of the steering (a
    first-order response) and ``max_steering_deg`` its lock: these three are what a
    driver of the car needs to know; the racing line does not use them.

    This layer cannot import the arena: these defaults are DeepRacer's car's (the arena's
    ``DEFAULT_CAR``) as measured, so that ``tracks`` used on its own (``slipstream
    tracks raceline``) plans with them; ``tests/arena/test_calibration.py`` fails when
    the car changes and they no longer match its measurement.
    """

    max_speed: float = 3.599
    max_lateral_accel: float = 3.363
    max_accel: float = 4.814
    max_brake: float = 4.85
    cornering: tuple[tuple[float, float], ...] = (
        (0.266, 3.556),
        (0.28, 3.448),
        (0.297, 3.34),
        (0.311, 3.232),
        (0.328, 3.126),
        (0.351, 3.02),
        (0.379, 2.914),
        (0.409, 2.808),
        (0.441, 2.705),
        (0.476, 2.603),
        (0.511, 2.5),
        (0.548, 2.398),
        (0.591, 2.293),
        (0.638, 2.188),
        (0.689, 2.08),
        (0.748, 1.975),
        (0.837, 1.828),
        (0.937, 1.723),
        (1.061, 1.62),
        (1.215, 1.512),
        (1.38, 1.403),
        (1.557, 1.295),
        (1.75, 1.188),
        (1.948, 1.084),
        (2.126, 0.984),
        (2.224, 0.897),
        (2.314, 0.661),
        (2.404, 0.565),
    )
    turning_wheelbase: float = 0.208
    understeer_gradient: float = 0.0273
    steering_time_constant: float = 0.5
    max_steering_deg: float = 30.0
    car_width: float = 0.196
    safety_margin: float = 0.05

    _ENVELOPE_ERROR = (
        "CarLimits.cornering must be (curvature, speed) rows of positive numbers "
        "by rising curvature"
    )

    def __post_init__(self) -> None:
        for key, value in asdict(self).items():
            if key == "cornering":
                continue
            may_be_zero = key in ("safety_margin", "understeer_gradient")
            if not np.isfinite(value) or value < 0 or (value == 0 and not may_be_zero):
                raise ValueError(f"CarLimits.{key} must be a positive number, got {value!r}")
        rows = np.asarray(self.cornering, dtype=float)
        shaped = rows.size == 0 or (rows.ndim == 2 and rows.shape[1] == 2)
        if not shaped or not np.isfinite(rows).all() or (rows <= 0).any():
            raise ValueError(self._ENVELOPE_ERROR)
        if rows.size and (np.diff(rows[:, 0]) <= 0).any():
            raise ValueError(self._ENVELOPE_ERROR)

    def corner_speed(self, curvature: np.ndarray | float) -> np.ndarray:
        """The highest speed the car holds on a circle of ``curvature`` (1/m): grip, the
        cornering envelope (beyond its tightest circle, that circle's speed) and top speed."""
        bend = np.abs(np.asarray(curvature, dtype=float))
        with np.errstate(divide="ignore"):
            speed = np.minimum(np.sqrt(self.max_lateral_accel / bend), self.max_speed)
        if self.cornering:
            rows = np.asarray(self.cornering, dtype=float)
            speed = np.minimum(speed, np.interp(bend, rows[:, 0], rows[:, 1], left=np.inf))
        return speed

    def wheelbase_at(self, speed: float) -> float:
        """The steering's effective wheelbase (m) at ``speed`` m/s: ``tan(steer) / curvature``."""
        return self.turning_wheelbase + self.understeer_gradient * speed**2

    @property
    def clearance(self) -> float:
        """Distance the line keeps from each border: half the car plus the margin."""
        return self.car_width / 2 + self.safety_margin


@dataclass(frozen=True, eq=False)
class RacingLine:
    """A driven path with its speed profile; loops repeat the first point at the end."""

    points: np.ndarray
    arc_length: np.ndarray
    curvature: np.ndarray
    speed: np.ndarray
    lap_time: float
    limits: CarLimits
    is_loop: bool
    track_name: str = ""
    direction: str = "ccw"

    @property
    def length(self) -> float:
        """Path length in metres."""
        return float(self.arc_length[-1])

    def to_dict(self, include_points: bool = True) -> dict[str, Any]:
        """JSON-ready summary; ``include_points`` adds the per-point arrays (rounded)."""
        doc: dict[str, Any] = {
            "track": self.track_name,
            "direction": self.direction,
            "loop": self.is_loop,
            "length": round(self.length, 4),
            "lap_time": round(self.lap_time, 4),
            "top_speed": round(float(self.speed.max()), 4),
            "min_speed": round(float(self.speed.min()), 4),
            "limits": asdict(self.limits),
        }
        if include_points:
            doc["points"] = np.round(self.points, 4).tolist()
            doc["arc_length"] = np.round(self.arc_length, 4).tolist()
            doc["curvature"] = np.round(self.curvature, 5).tolist()
            doc["speed"] = np.round(self.speed, 4).tolist()
        return doc


# ------------------------------------------------------------------ geometry helpers
def _resample(track: Track, step: float) -> np.ndarray:
    """Centre-line points at an even spacing (loops: without the repeated end point)."""
    count = max(round(track.length / step), 8)
    s = np.linspace(
        0.0, track.length, count + (0 if track.is_loop else 1), endpoint=not track.is_loop
    )
    c = track.waypoints
    cum = track.cumulative_length
    return np.stack([np.interp(s, cum, c[:, 0]), np.interp(s, cum, c[:, 1])], axis=1)


def _normals(points: np.ndarray, is_loop: bool) -> np.ndarray:
    if is_loop:
        tangent = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        tangent = np.gradient(points, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)


def _ray_hit(origins: np.ndarray, dirs: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance along each ray to its first crossing of the polyline (inf if none)."""
    a, seg = polyline[:-1], np.diff(polyline, axis=0)
    rel = a[None, :, :] - origins[:, None, :]
    denom = dirs[:, None, 0] * seg[None, :, 1] - dirs[:, None, 1] * seg[None, :, 0]
    safe = np.where(np.abs(denom) < 1e-12, np.nan, denom)
    t = (rel[..., 0] * seg[None, :, 1] - rel[..., 1] * seg[None, :, 0]) / safe
    u = (rel[..., 0] * dirs[:, None, 1] - rel[..., 1] * dirs[:, None, 0]) / safe
    ok = (t >= 0) & (u >= 0) & (u <= 1)
    return np.where(ok, t, np.inf).min(axis=1)


def _path_curvature(points: np.ndarray, is_loop: bool, window: float) -> np.ndarray:
    """Signed curvature averaged over about ``window`` metres: heading change / distance."""
    step = float(np.mean(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    half = max(1, round(window / (2 * step)))
    if is_loop:
        ext = np.vstack([points[-half:], points, points[: half + 1]])
        centre = np.arange(len(points)) + half
    else:
        ext, centre = points, np.arange(len(points))
    seg = np.diff(ext, axis=0)
    heading = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
    seg_len = np.linalg.norm(seg, axis=1)
    mid = np.cumsum(seg_len) - 0.5 * seg_len
    before = np.clip(centre - half, 0, len(seg) - 1)
    after = np.clip(centre + half - 1, 0, len(seg) - 1)
    dist = np.maximum(mid[after] - mid[before], 1e-9)
    return np.where(after > before, (heading[after] - heading[before]) / dist, 0.0)


# ---------------------------------------------------------------- the optimisation
def _second_difference(n: int, is_loop: bool) -> np.ndarray:
    """Matrix of second differences ``x[i-1] - 2 x[i] + x[i+1]`` (cyclic for loops)."""
    rows = n if is_loop else n - 2
    d = np.zeros((rows, n))
    r = np.arange(rows)
    centre = r if is_loop else r + 1
    for shift, weight in ((-1, 1.0), (0, -2.0), (1, 1.0)):
        d[r, (centre + shift) % n] = weight
    return d


def _step_to_boundary(values: np.ndarray, deltas: np.ndarray) -> float:
    """Largest step in [0, 1] keeping every ``values + step * deltas`` non-negative."""
    shrinking = deltas < 0
    if not shrinking.any():
        return 1.0
    return min(1.0, float(np.min(-values[shrinking] / deltas[shrinking])))


def _newton_step(
    system: np.ndarray,
    residual: np.ndarray,
    slacks: tuple[np.ndarray, np.ndarray],
    duals: tuple[np.ndarray, np.ndarray],
    c_lo: np.ndarray,
    c_hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interior-point Newton step aiming the complementarity products at ``s*z + c``."""
    (s_lo, s_hi), (z_lo, z_hi) = slacks, duals
    dx = np.linalg.solve(system, -residual + c_lo / s_lo - c_hi / s_hi)
    return dx, (c_lo - z_lo * dx) / s_lo, (c_hi + z_hi * dx) / s_hi


def _longest_step(
    slacks: tuple[np.ndarray, np.ndarray],
    duals: tuple[np.ndarray, np.ndarray],
    dx: np.ndarray,
    dz_lo: np.ndarray,
    dz_hi: np.ndarray,
) -> float:
    """Largest step in [0, 1] keeping slacks and duals non-negative."""
    pairs = ((slacks[0], dx), (slacks[1], -dx), (duals[0], dz_lo), (duals[1], dz_hi))
    return min(_step_to_boundary(v, d) for v, d in pairs)


def solve_box_qp(
    hessian: np.ndarray,
    gradient: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    tol: float = 1e-10,
    max_iter: int = 80,
) -> np.ndarray:
    """Minimise ``x'Hx/2 + g'x`` subject to ``lower < x < upper`` (H positive definite).

    A primal-dual interior-point method with Mehrotra's predictor-corrector steps:
    a few dozen dense solves whatever the conditioning, deterministic, and the
    answer stays strictly inside the box.
    """
    n = len(gradient)
    x = 0.5 * (lower + upper)
    scale = max(float(np.abs(gradient).max()), float(np.abs(hessian).max()), 1e-12)
    z_lo = np.full(n, scale)
    z_hi = np.full(n, scale)
    for _ in range(max_iter):
        s_lo, s_hi = x - lower, upper - x
        residual = hessian @ x + gradient - z_lo + z_hi
        mu = float(z_lo @ s_lo + z_hi @ s_hi) / (2 * n)
        if mu < tol * scale and np.abs(residual).max() < tol * scale:
            break
        system = hessian + np.diag(z_lo / s_lo + z_hi / s_hi)
        slacks, duals = (s_lo, s_hi), (z_lo, z_hi)
        dx, dz_lo, dz_hi = _newton_step(system, residual, slacks, duals, -z_lo * s_lo, -z_hi * s_hi)
        a = _longest_step(slacks, duals, dx, dz_lo, dz_hi)
        gap = (z_lo + a * dz_lo) @ (s_lo + a * dx) + (z_hi + a * dz_hi) @ (s_hi - a * dx)
        target = (float(gap) / (2 * n) / mu) ** 3 * mu
        dx, dz_lo, dz_hi = _newton_step(
            system,
            residual,
            slacks,
            duals,
            target - z_lo * s_lo - dx * dz_lo,
            target - z_hi * s_hi + dx * dz_hi,
        )
        a = 0.99 * _longest_step(slacks, duals, dx, dz_lo, dz_hi)
        x, z_lo, z_hi = x + a * dx, z_lo + a * dz_lo, z_hi + a * dz_hi
    return x


def _min_curvature_offsets(
    ref: np.ndarray, normals: np.ndarray, lower: np.ndarray, upper: np.ndarray, is_loop: bool
) -> np.ndarray:
    """Lateral offsets minimising the bending of ``ref + offset * normal``.

    The bend at point ``i`` is the second difference of the path projected on the
    normal there: about ``curvature * spacing^2`` for evenly spaced points. Its
    tangential part (uneven spacing) is left out, so the line may cut apexes.
    """
    d = _second_difference(len(ref), is_loop)
    centre = np.arange(len(ref)) if is_loop else np.arange(1, len(ref) - 1)
    a = d * (normals[centre] @ normals.T)
    b = np.einsum("ij,ij->i", d @ ref, normals[centre])
    hessian = a.T @ a
    hessian[np.diag_indices_from(hessian)] += 1e-9 * float(np.abs(hessian).max())
    return solve_box_qp(hessian, a.T @ b, lower, upper)


def _border_distances(points: np.ndarray, track: Track) -> np.ndarray:
    """Distance from each point to the nearer border polyline."""
    left = project_onto_polyline(points, track.left).distance
    right = project_onto_polyline(points, track.right).distance
    return np.minimum(left, right), left < right


def _offset_bounds(
    track: Track, ref: np.ndarray, normals: np.ndarray, clearance: float
) -> tuple[np.ndarray, np.ndarray]:
    """Box for the offsets: the borders as met along each normal, less the clearance."""
    s = track.project(ref).arc_length
    cum = track.cumulative_length
    left = _ray_hit(ref, normals, track.left)
    right = _ray_hit(ref, -normals, track.right)
    left = np.where(np.isfinite(left), left, np.interp(s, cum, track.left_half_widths))
    right = np.where(np.isfinite(right), right, np.interp(s, cum, track.right_half_widths))
    return _ordered(clearance - right, left - clearance)


def _ordered(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where a box is empty (road narrower than the car plus margins) keep its middle."""
    squeezed = upper - lower < 2e-6
    mid = 0.5 * (lower + upper)
    return np.where(squeezed, mid - 1e-6, lower), np.where(squeezed, mid + 1e-6, upper)


# ------------------------------------------------------------------ speed profile
def _passes(cap: np.ndarray, ds: np.ndarray, limits: CarLimits, v_start: float) -> np.ndarray:
    """Forward (acceleration) then backward (braking) pass along an open sequence."""
    v = cap.copy()
    v[0] = min(v[0], v_start)
    for i in range(len(v) - 1):
        v[i + 1] = min(v[i + 1], np.sqrt(v[i] ** 2 + 2 * limits.max_accel * ds[i]))
    for i in range(len(v) - 2, -1, -1):
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * limits.max_brake * ds[i]))
    return v


def speed_profile(
    points: np.ndarray, limits: CarLimits, is_loop: bool
) -> tuple[np.ndarray, np.ndarray, float]:
    """Curvature, speed and lap time along a path (loops: no repeated end point).

    A loop gets the steady-state flying lap: the passes start at the slowest corner,
    where the speed is pinned at its grip limit, and run once round. An open path
    starts from standstill.
    """
    curvature = _path_curvature(points, is_loop, CURVATURE_WINDOW)
    ring = np.vstack([points, points[:1]]) if is_loop else points
    ds = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    cap = limits.corner_speed(curvature)
    if is_loop:
        start = int(np.argmin(cap))
        order = np.r_[start : len(cap), 0 : start + 1]
        seg_order = np.r_[start : len(ds), 0:start]
        v = _passes(cap[order], ds[seg_order], limits, cap[start])
        speed = np.empty_like(cap)
        speed[order[:-1]] = v[:-1]
        speed = np.append(speed, speed[0])
        curvature = np.append(curvature, curvature[0])
    else:
        speed = _passes(cap, ds, limits, 0.0)
    lap_time = float(np.sum(2 * ds / (speed[:-1] + speed[1:])))
    return curvature, speed, lap_time


def profile_path(
    points: np.ndarray,
    limits: CarLimits = CarLimits(),
    *,
    is_loop: bool = True,
    track_name: str = "",
    direction: str = "ccw",
) -> RacingLine:
    """Speed profile of any path (loops: with or without the repeated end point)."""
    pts = np.asarray(points, dtype=float)
    if is_loop and np.allclose(pts[0], pts[-1]):
        pts = pts[:-1]
    curvature, speed, lap_time = speed_profile(pts, limits, is_loop)
    closed = np.vstack([pts, pts[:1]]) if is_loop else pts
    return RacingLine(
        points=closed,
        arc_length=cumulative_length(closed),
        curvature=curvature,
        speed=speed,
        lap_time=lap_time,
        limits=limits,
        is_loop=is_loop,
        track_name=track_name,
        direction=direction,
    )


def centerline_profile(
    track: Track, limits: CarLimits = CarLimits(), step: float = STEP
) -> RacingLine:
    """The centre line driven at the limit: the baseline a racing line must beat."""
    return profile_path(
        _resample(track, step),
        limits,
        is_loop=track.is_loop,
        track_name=track.name,
        direction=track.direction,
    )


def compute_racing_line(
    track: Track, limits: CarLimits = CarLimits(), *, step: float = STEP, max_rounds: int = 4
) -> RacingLine:
    """Minimum-curvature racing line of ``track`` with its physical-limit lap time.

    ``step`` is the spacing of the optimised points (metres). Each round checks the
    real distance from every point to the borders and tightens the box where the
    clearance is short (borders not perpendicular to the normals), at most
    ``max_rounds`` times. Deterministic: no randomness anywhere.
    """
    ref = _resample(track, step)
    normals = _normals(ref, track.is_loop)
    lower, upper = _offset_bounds(track, ref, normals, limits.clearance)
    for _ in range(max_rounds):
        offsets = _min_curvature_offsets(ref, normals, lower, upper, track.is_loop)
        points = ref + offsets[:, None] * normals
        dist, nearer_left = _border_distances(points, track)
        short = np.maximum(limits.clearance - dist, 0.0)
        if short.max() < 1e-4:
            break
        lower, upper = _ordered(
            np.where(nearer_left, lower, lower + short), np.where(nearer_left, upper - short, upper)
        )
    return profile_path(
        points, limits, is_loop=track.is_loop, track_name=track.name, direction=track.direction
    )
