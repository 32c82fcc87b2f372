"""Build DeepRacer's reward-function ``params`` dict for one car.

Every key of racing-rules.md is present every step; the object keys appear only when
the race has other objects (obstacles, bots or other cars).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from tracks.track import Projection, Track

CAMERA_HALF_FOV_DEG = 64.7 / 2.0
CAMERA_RANGE_M = 6.0


@dataclass(frozen=True)
class ObjectsView:
    """Other objects on track at one instant (all arrays of shape ``(K,)`` or ``(K, 2)``)."""

    location: np.ndarray
    heading_deg: np.ndarray
    speed: np.ndarray
    projection: Projection

    @classmethod
    def empty(cls, track: Track) -> ObjectsView:
        """No objects."""
        z = np.zeros((0, 2))
        return cls(z, np.zeros(0), np.zeros(0), track.project(z))

    def __len__(self) -> int:
        return len(self.location)

    def without(self, index: int) -> ObjectsView:
        """The same objects less the one at ``index`` (a car does not see itself)."""
        keep = np.arange(len(self)) != index
        projection = Projection(
            **{f.name: getattr(self.projection, f.name)[keep] for f in fields(Projection)}
        )
        return ObjectsView(
            self.location[keep], self.heading_deg[keep], self.speed[keep], projection
        )


def heading_degrees(yaw: float) -> float:
    """Yaw in radians to DeepRacer's heading in degrees, in (-180, 180]."""
    deg = math.degrees(yaw) % 360.0
    return deg - 360.0 if deg > 180.0 else deg


def closest_objects(track: Track, car_arc: float, object_arcs: np.ndarray) -> list[int]:
    """``[behind, ahead]`` indices of the objects nearest along the track."""
    gaps = object_arcs - car_arc
    if track.is_loop:
        gaps = np.mod(gaps, track.length)
    ahead = int(np.argmin(np.where(gaps >= 0, gaps, np.inf)))
    behind_gap = gaps if not track.is_loop else gaps - track.length
    behind = int(np.argmax(np.where(behind_gap < 0, behind_gap, -np.inf)))
    if not track.is_loop and not (gaps < 0).any():
        behind = ahead
    if not track.is_loop and not (gaps >= 0).any():
        ahead = behind
    return [behind, ahead]


def object_in_camera(x: float, y: float, yaw: float, location: np.ndarray) -> bool:
    """Whether a point lies in the front camera's horizontal view and range."""
    dx, dy = location[0] - x, location[1] - y
    dist = math.hypot(dx, dy)
    if dist > CAMERA_RANGE_M or dist < 1e-9:
        return False
    bearing = math.degrees(math.atan2(dy, dx) - yaw)
    bearing = (bearing + 180.0) % 360.0 - 180.0
    return abs(bearing) <= CAMERA_HALF_FOV_DEG


def build_params(
    *,
    track: Track,
    is_reversed: bool,
    model_point: np.ndarray,
    yaw: float,
    projection: Projection,
    index: int,
    progress: float,
    steps: int,
    speed: float,
    steering_angle: float,
    all_wheels_on_track: bool,
    is_offtrack: bool,
    is_crashed: bool,
    objects: ObjectsView,
    waypoints: list[tuple[float, float]],
) -> dict[str, Any]:
    """The params dict for the car whose projection is row ``index`` of ``projection``."""
    x, y = float(model_point[0]), float(model_point[1])
    seg = int(projection.segment[index])
    params: dict[str, Any] = {
        "all_wheels_on_track": bool(all_wheels_on_track),
        "x": x,
        "y": y,
        "heading": heading_degrees(yaw),
        "speed": float(speed),
        "steering_angle": float(steering_angle),
        "progress": float(progress),
        "steps": int(steps),
        "distance_from_center": float(projection.distance_from_center[index]),
        "track_width": float(projection.track_width[index]),
        "track_length": float(track.length),
        "waypoints": waypoints,
        "closest_waypoints": [seg, seg + 1],
        "is_left_of_center": bool(projection.offset[index] > 0),
        "is_reversed": bool(is_reversed),
        "is_offtrack": bool(is_offtrack),
        "is_crashed": bool(is_crashed),
        "projection_distance": float(projection.arc_length[index]),
    }
    if len(objects):
        op = objects.projection
        params.update(
            {
                "closest_objects": closest_objects(
                    track, float(projection.arc_length[index]), op.arc_length
                ),
                "objects_location": [tuple(map(float, p)) for p in objects.location],
                "objects_left_of_center": [bool(o > 0) for o in op.offset],
                "objects_distance": [float(a) for a in op.arc_length],
                "objects_distance_from_center": [float(d) for d in op.distance_from_center],
                "objects_heading": [float(h) for h in objects.heading_deg],
                "objects_speed": [float(v) for v in objects.speed],
            }
        )
        ahead = params["closest_objects"][1]
        params["object_in_camera"] = object_in_camera(x, y, yaw, objects.location[ahead])
    return params


def check_reward(value: Any, car: str, step: int, params: dict[str, Any]) -> float:
    """Validate a reward: a finite number within +-1e5, else a ``ValueError`` naming all."""
    try:
        reward = float(value)
    except (TypeError, ValueError):
        reward = math.nan
    if not math.isfinite(reward) or abs(reward) > 1e5:
        shown = {k: v for k, v in params.items() if k != "waypoints"}
        raise ValueError(
            f"reward function of car {car!r} returned {value!r} at step {step}; rewards must "
            f"be finite numbers within +-1e5. params: {shown}"
        )
    return reward
