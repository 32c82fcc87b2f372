"""The privileged state a training critic may see: the car's situation, not its sensors.

``--critic privileged`` gives PPO's critic this vector instead of the camera and lidar:
the value of a state is easier to learn from where the car is, how it points and how fast
it goes than from pixels, and an MLP on ~30 numbers costs a fraction of a CNN's update.
The actor keeps only its sensors and is the only network exported, so a model trained so
races exactly like any other. Everything here is read off DeepRacer's reward ``params``
(the same facts a reward function gets) and the track, in the training workers.

The vector, :data:`PRIVILEGED_SIZE` float32 values:

- signed distance from the centre line over the half width (left positive);
- the track's heading relative to the car's at :data:`LOOKAHEAD_M` metres ahead, as
  sine and cosine (how the road bends ahead);
- speed over the car's top speed, steering over its lock, all wheels on track (0/1),
  progress / 100;
- the :data:`AHEAD` nearest other objects (boxes, bots, cars) ahead within
  :data:`SIGHT_M` and the nearest behind within it: present (0/1), gap over
  :data:`SIGHT_M`, signed distance from the centre over the half width, and speed
  relative to the car's over the top speed (zeros when absent).
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np

from arena.car_spec import DEFAULT_CAR
from tracks.track import Track

# What PPO's critic may read: the actor's sensors, or this module's vector.
CriticInput = Literal["sensors", "privileged"]
# The observation group the critic reads (beside the sensors' groups).
PRIVILEGED_GROUP = "privileged"
LOOKAHEAD_M = (0.0, 0.5, 1.0, 2.0, 3.0)
SIGHT_M = 6.0  # the camera's range (arena.params.CAMERA_RANGE_M)
AHEAD = 2
_OBJECT_FEATURES = 4
PRIVILEGED_SIZE = 1 + 2 * len(LOOKAHEAD_M) + 4 + _OBJECT_FEATURES * (AHEAD + 1)


def _signed_offset(distance: float, left: bool, half_width: float) -> float:
    return (distance if left else -distance) / half_width


def privileged_state(track: Track, params: dict[str, Any]) -> np.ndarray:
    """The privileged vector of the car whose reward ``params`` are given (module doc).

    ``track`` is the race's track in its driving direction (``RacingEnv.track``).
    """
    half = max(0.5 * float(params["track_width"]), 1e-6)
    arc = float(params["projection_distance"])
    headings = track.heading_at(arc + np.asarray(LOOKAHEAD_M))
    relative = headings - math.radians(float(params["heading"]))
    speed = float(params["speed"])
    car = [
        _signed_offset(params["distance_from_center"], params["is_left_of_center"], half),
        *np.sin(relative),
        *np.cos(relative),
        speed / DEFAULT_CAR.max_speed,
        float(params["steering_angle"]) / DEFAULT_CAR.max_steering_deg,
        float(params["all_wheels_on_track"]),
        float(params["progress"]) / 100.0,
    ]
    return np.concatenate([np.asarray(car), _objects(track, params, arc, half, speed)]).astype(
        np.float32
    )


def _objects(
    track: Track, params: dict[str, Any], arc: float, half: float, speed: float
) -> np.ndarray:
    """The object part: :data:`AHEAD` nearest ahead, then the nearest behind."""
    out = np.zeros((AHEAD + 1, _OBJECT_FEATURES))
    if not params["objects_distance"]:
        return out.ravel()
    gaps = np.atleast_1d(track.arc_delta(arc, np.asarray(params["objects_distance"], dtype=float)))
    ahead = [i for i in np.argsort(gaps) if 0.0 <= gaps[i] <= SIGHT_M][:AHEAD]
    behind = [i for i in np.argsort(-gaps) if -SIGHT_M <= gaps[i] < 0.0][:1]
    rows = list(range(len(ahead))) + ([AHEAD] if behind else [])
    for row, i in zip(rows, ahead + behind, strict=True):
        out[row] = (
            1.0,
            gaps[i] / SIGHT_M,
            _signed_offset(
                params["objects_distance_from_center"][i], params["objects_left_of_center"][i], half
            ),
            (float(params["objects_speed"][i]) - speed) / DEFAULT_CAR.max_speed,
        )
    return out.ravel()
