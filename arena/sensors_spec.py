"""The sensors a car can carry: names, DeepRacer spellings, shapes and their numbers.

Every figure of a sensor (camera intrinsics and mounting, lidar beams, ranges, noise and
mounting) is written here once; :mod:`arena.camera`, :mod:`arena.lidar` and
:mod:`arena.params` read it from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from gymnasium import spaces
from pydantic import BaseModel, ConfigDict, Field

SensorName = Literal["camera", "stereo", "lidar", "sector_lidar", "discretized_sector_lidar"]
SENSOR_NAMES: tuple[str, ...] = get_args(SensorName)
IMAGE_SENSORS: tuple[str, ...] = ("camera", "stereo")
"""The sensors that see the road (a lidar sees cars and boxes only)."""
DEEPRACER_SENSOR = {
    "camera": "FRONT_FACING_CAMERA",
    "stereo": "STEREO_CAMERAS",
    "lidar": "LIDAR",
    "sector_lidar": "SECTOR_LIDAR",
    "discretized_sector_lidar": "DISCRETIZED_SECTOR_LIDAR",
}
FROM_DEEPRACER_SENSOR = {v: k for k, v in DEEPRACER_SENSOR.items()}

CAMERA_HEIGHT = 120
CAMERA_WIDTH = 160
LIDAR_BEAMS = 64
LIDAR_FOV_DEG = 300.0
LIDAR_MIN_RANGE = 0.15
LIDAR_MAX_RANGE = 12.0
LIDAR_CLIP = 1.0
LIDAR_NOISE_STD = 0.01
LIDAR_MOUNT_FORWARD = 0.0
LIDAR_MOUNT_HEIGHT = 0.07
SECTOR_THRESHOLD = 0.5


@dataclass(frozen=True)
class CameraSpec:
    """Intrinsics and mounting of one camera (stereo: two, ``stereo_baseline`` apart).

    Mount offsets are from the car origin (on the ground, at the car's reference point),
    in the car frame; ``near``/``far`` bound what is drawn (the horizon is ``far`` away).
    """

    width: int = CAMERA_WIDTH
    height: int = CAMERA_HEIGHT
    hfov_deg: float = 64.7
    pitch_down_deg: float = 15.0
    mount_forward: float = 0.09
    mount_height: float = 0.12
    stereo_baseline: float = 0.06
    near: float = 0.01
    far: float = 30.0

    @property
    def focal(self) -> float:
        """Focal length in pixels (square pixels)."""
        return 0.5 * self.width / math.tan(math.radians(0.5 * self.hfov_deg))

    @property
    def vfov_deg(self) -> float:
        """Vertical field of view in degrees."""
        return math.degrees(2.0 * math.atan(0.5 * self.height / self.focal))


DEFAULT_CAMERA = CameraSpec()
"""The front camera every car carries (each of the two, for stereo)."""


class LidarConfig(BaseModel):
    """DeepRacer's ``lidar_config`` for the sector lidars."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    num_sectors: int = Field(default=8, ge=1, le=64)
    num_values_per_sector: int = Field(default=8, ge=1, le=64)
    clipping_dist: float = Field(default=2.0, gt=0.0, le=LIDAR_MAX_RANGE)


def check_sensors(sensors: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Validate a sensor combination; returns it as a tuple in canonical order.

    At least one sensor; at most one camera (``camera`` or ``stereo``) and at most one
    lidar kind. Raises ``ValueError`` with a message naming the problem.
    """
    names = tuple(sensors)
    if not names:
        raise ValueError("a car needs at least one sensor")
    unknown = [s for s in names if s not in SENSOR_NAMES]
    if unknown:
        raise ValueError(f"unknown sensor(s) {unknown}; choose from {list(SENSOR_NAMES)}")
    if len(set(names)) != len(names):
        raise ValueError(f"sensor listed twice in {list(names)}")
    if "camera" in names and "stereo" in names:
        raise ValueError("choose one of 'camera' and 'stereo', not both")
    lidars = [s for s in names if "lidar" in s]
    if len(lidars) > 1:
        raise ValueError(f"choose one lidar kind, got {lidars}")
    return tuple(s for s in SENSOR_NAMES if s in names)


MAX_STACK_SIZE = 8
"""The most frames a car's observation may stack (DeepRacer's ``stack_size``)."""


def _frame_space(name: str, lidar: LidarConfig) -> spaces.Box:
    """The observation space of one frame of one sensor."""
    if name == "camera":
        return spaces.Box(0, 255, (CAMERA_HEIGHT, CAMERA_WIDTH, 1), dtype=np.uint8)
    if name == "stereo":
        return spaces.Box(0, 255, (CAMERA_HEIGHT, CAMERA_WIDTH, 2), dtype=np.uint8)
    if name == "lidar":
        return spaces.Box(LIDAR_MIN_RANGE, LIDAR_CLIP, (LIDAR_BEAMS,), dtype=np.float32)
    if name == "sector_lidar":
        return spaces.Box(0.0, 1.0, (lidar.num_sectors,), dtype=np.float32)
    if name == "discretized_sector_lidar":
        size = lidar.num_sectors * lidar.num_values_per_sector
        return spaces.Box(0.0, 1.0, (size,), dtype=np.float32)
    raise ValueError(f"unknown sensor {name!r}; choose from {list(SENSOR_NAMES)}")


def sensor_space(name: str, lidar: LidarConfig | None = None, stack_size: int = 1) -> spaces.Box:
    """The observation space of one sensor: ``stack_size`` frames along the last axis.

    A stack holds the frames oldest first, so the camera's ``120 x 160 x 1`` becomes
    ``120 x 160 x k``, stereo ``120 x 160 x 2k`` (each frame's two channels together) and a
    lidar's ``n`` values ``n * k``.
    """
    if not 1 <= stack_size <= MAX_STACK_SIZE:
        raise ValueError(f"stack_size must be 1 to {MAX_STACK_SIZE}, got {stack_size}")
    frame = _frame_space(name, lidar or LidarConfig())
    if stack_size == 1:
        return frame
    low = np.concatenate([frame.low] * stack_size, axis=-1)
    high = np.concatenate([frame.high] * stack_size, axis=-1)
    return spaces.Box(low, high, dtype=frame.dtype)


def observation_space(
    sensors: tuple[str, ...], lidar: LidarConfig | None = None, stack_size: int = 1
) -> spaces.Dict:
    """A car's observation space: a Dict with one entry per sensor (see :func:`sensor_space`)."""
    return spaces.Dict(
        {name: sensor_space(name, lidar, stack_size) for name in check_sensors(sensors)}
    )
