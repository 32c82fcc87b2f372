"""Build DeepRacer's reward-function ``params`` dict for one car.

Every key of racing-rules.md, plus the community simapp's ``sim_time``, is present every
step in every race type. Without other objects (obstacles, bots or other cars) the object
keys carry DeepRacer's defaults: ``closest_objects`` ``[0, 0]``, ``object_in_camera``
``False`` and empty ``objects_*`` lists. Like DeepRacer, which hands the reward function
a deep copy, every dict built here and every :func:`params_copy` has its own lists.
"""

from __future__ import annotations

import math
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from arena.sensors_spec import DEFAULT_CAMERA
from tracks.track import Projection, Track

CAMERA_HALF_FOV_DEG = 0.5 * DEFAULT_CAMERA.hfov_deg
CAMERA_RANGE_M = 6.0


@dataclass(frozen=True)
class ObjectsView:
    """Other objects on track at one instant, as the params' object lists (one entry each).

    Built once per step from arrays with :meth:`of`; :meth:`without` then hands each car
    the others cheaply.
    """

    location: tuple[tuple[float, float], ...]
    heading_deg: tuple[float, ...]
    speed: tuple[float, ...]
    left_of_center: tuple[bool, ...]
    distance: tuple[float, ...]
    distance_from_center: tuple[float, ...]

    @classmethod
    def of(
        cls,
        location: np.ndarray,
        heading_deg: np.ndarray,
        speed: np.ndarray,
        projection: Projection,
    ) -> ObjectsView:
        """The view of objects at ``location`` ``(K, 2)`` whose centre-line projection is given."""
        return cls(
            location=tuple(map(tuple, np.asarray(location, dtype=float).tolist())),
            heading_deg=tuple(np.asarray(heading_deg, dtype=float).tolist()),
            speed=tuple(np.asarray(speed, dtype=float).tolist()),
            left_of_center=tuple((projection.offset > 0).tolist()),
            distance=tuple(projection.arc_length.tolist()),
            distance_from_center=tuple(projection.distance_from_center.tolist()),
        )

    @classmethod
    def empty(cls) -> ObjectsView:
        """No objects."""
        return cls((), (), (), (), (), ())

    def __len__(self) -> int:
        return len(self.location)

    def without(self, index: int) -> ObjectsView:
        """The same objects less the one at ``index`` (a car does not see itself)."""
        columns = (
            self.location,
            self.heading_deg,
            self.speed,
            self.left_of_center,
            self.distance,
            self.distance_from_center,
        )
        return ObjectsView(*(values[:index] + values[index + 1 :] for values in columns))


def heading_degrees(yaw: float) -> float:
    """Yaw in radians to DeepRacer's heading in degrees, in (-180, 180]."""
    deg = math.degrees(yaw) % 360.0
    return deg - 360.0 if deg > 180.0 else deg


def closest_objects(track: Track, car_arc: float, object_arcs: Sequence[float]) -> list[int]:
    """``[behind, ahead]`` indices of the objects nearest along the track (first on ties)."""
    gaps = [arc - car_arc for arc in object_arcs]
    order = range(len(gaps))
    if track.is_loop:
        gaps = [gap % track.length for gap in gaps]
        return [max(order, key=gaps.__getitem__), min(order, key=gaps.__getitem__)]
    ahead = [i for i in order if gaps[i] >= 0]
    behind = [i for i in order if gaps[i] < 0]
    nearest_ahead = min(ahead, key=gaps.__getitem__) if ahead else None
    nearest_behind = max(behind, key=gaps.__getitem__) if behind else None
    if nearest_ahead is None:
        nearest_ahead = nearest_behind
    if nearest_behind is None:
        nearest_behind = nearest_ahead
    return [int(nearest_behind), int(nearest_ahead)]


def object_in_camera(x: float, y: float, yaw: float, location: Sequence[float]) -> bool:
    """Whether a point lies in the front camera's horizontal view and range."""
    dx, dy = location[0] - x, location[1] - y
    dist = math.hypot(dx, dy)
    if dist > CAMERA_RANGE_M or dist < 1e-9:
        return False
    bearing = math.degrees(math.atan2(dy, dx) - yaw)
    bearing = (bearing + 180.0) % 360.0 - 180.0
    return abs(bearing) <= CAMERA_HALF_FOV_DEG


# The params' list values. Their items are tuples or scalars (immutable), so copying the
# lists copies the dict as deeply as DeepRacer's ``copy.deepcopy`` does.
LIST_KEYS = (
    "waypoints",
    "closest_waypoints",
    "closest_objects",
    "objects_location",
    "objects_left_of_center",
    "objects_distance",
    "objects_distance_from_center",
    "objects_heading",
    "objects_speed",
)


def params_copy(params: dict[str, Any]) -> dict[str, Any]:
    """A copy of ``params`` that shares no list with it (what a reward function gets)."""
    copy = params.copy()
    for key in LIST_KEYS:
        value = copy.get(key)
        if value is not None:
            copy[key] = value[:]
    return copy


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
    sim_time: float,
) -> dict[str, Any]:
    """The params dict for the car whose projection is row ``index`` of ``projection``.

    ``waypoints`` is copied (the dict owns all its lists); ``sim_time`` is the simulated
    seconds since the episode began."""
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
        "waypoints": waypoints[:],
        "closest_waypoints": [seg, seg + 1],
        "is_left_of_center": bool(projection.offset[index] > 0),
        "is_reversed": bool(is_reversed),
        "is_offtrack": bool(is_offtrack),
        "is_crashed": bool(is_crashed),
        "projection_distance": float(projection.arc_length[index]),
        "sim_time": float(sim_time),
        # DeepRacer's defaults when there are no objects; filled in below when there are.
        "closest_objects": [0, 0],
        "objects_location": list(objects.location),
        "objects_left_of_center": list(objects.left_of_center),
        "objects_distance": list(objects.distance),
        "objects_distance_from_center": list(objects.distance_from_center),
        "objects_heading": list(objects.heading_deg),
        "objects_speed": list(objects.speed),
        "object_in_camera": False,
    }
    if len(objects):
        nearest = closest_objects(track, float(projection.arc_length[index]), objects.distance)
        params["closest_objects"] = nearest
        params["object_in_camera"] = object_in_camera(x, y, yaw, objects.location[nearest[1]])
    return params


class RewardRaised(RuntimeError):
    """A reward function raised; the message names the car, the step, the line and the cause
    (which is also the exception's ``__cause__``)."""


def deepest_line(exc: BaseException, filename: str) -> int | None:
    """The line of the deepest traceback frame of ``exc`` in ``filename``, if any."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if f.filename == filename]
    return frames[-1].lineno if frames else None


def call_reward(
    fn: Callable[[dict[str, Any]], Any], car: str, step: int, params: dict[str, Any]
) -> float:
    """``fn`` on its own copy of ``params`` (as DeepRacer), checked by :func:`check_reward`.

    An exception it raises becomes a :class:`RewardRaised` naming the car, the step and the
    line of ``fn``'s file it came from (else the deepest line).
    """
    try:
        value = fn(params_copy(params))
    except Exception as exc:
        source = getattr(getattr(fn, "__code__", None), "co_filename", "")
        line = deepest_line(exc, source)
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        where = f"{source}, line {line}" if line else f"{frame.filename}, line {frame.lineno}"
        raise RewardRaised(
            f"reward function of car {car!r} raised at step {step} ({where}): "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    return check_reward(value, car, step, params)


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
