"""Where things start: car grids, obstacle boxes, bot cars, and respawn poses."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arena.config import ConfigError, ObstacleConfig, RaceConfig
from tracks.track import Track

GRID_GAP_M = 0.8
START_CLEAR_M = 1.5
RESPAWN_BEHIND_OBSTACLE_M = 1.0


@dataclass(frozen=True)
class Placement:
    """A pose on the track: arc length, lane offset (metres, left positive) and world pose."""

    arc: float
    offset: float
    x: float
    y: float
    yaw: float


def place(track: Track, arc: float, lane: str | float) -> Placement:
    """The pose at arc length ``arc`` on ``lane`` ('center', 'inner', 'outer' or metres)."""
    arc = float(track.wrap_arc_length(arc))
    pos, heading = track.pose_at(np.array([arc]), lane)
    offset = float(track.lane_offset(np.array([arc]), lane)[0])
    return Placement(arc, offset, float(pos[0, 0]), float(pos[0, 1]), float(heading[0]))


def start_arc(config: RaceConfig, track: Track, episode: int) -> float:
    """Arc length of the start point; training episodes move on by a step each time."""
    pct = config.start_offset_pct
    if config.mode == "training":
        pct += episode * config.training_start_step_pct
    return float(track.wrap_arc_length((pct % 100.0) * track.length / 100.0))


def car_grid(config: RaceConfig, track: Track, arc0: float) -> list[Placement]:
    """Controlled cars' starting places: the centre line for one car, else a staggered grid
    on alternating lanes, each car ``GRID_GAP_M`` behind the one before."""
    if len(config.cars) == 1:
        return [place(track, arc0, "center")]
    return [
        place(track, arc0 - i * GRID_GAP_M, "inner" if i % 2 == 0 else "outer")
        for i in range(len(config.cars))
    ]


def obstacle_places(
    config: ObstacleConfig, track: Track, arc0: float, rng: np.random.Generator
) -> list[tuple[Placement, str]]:
    """Boxes at the configured ``(progress, lane)`` places or random ones on alternating lanes.

    Random places keep ``min_gap_m`` between boxes and ``START_CLEAR_M`` clear ahead of
    the start. Raises :class:`ConfigError` when the boxes cannot fit on the track.
    """
    if config.positions is not None:
        return [
            (place(track, arc0 + pct * track.length / 100.0, lane), lane)
            for pct, lane in config.positions
        ]
    usable = track.length - 2 * START_CLEAR_M
    slack = usable - config.count * config.min_gap_m
    if slack < 0:
        raise ConfigError(
            f"{config.count} boxes with {config.min_gap_m} m gaps need "
            f"{config.count * config.min_gap_m + 2 * START_CLEAR_M:.1f} m of track; "
            f"{track.name} is {track.length:.1f} m"
        )
    cuts = np.sort(rng.uniform(0.0, slack, size=config.count))
    arcs = START_CLEAR_M + cuts + config.min_gap_m * np.arange(config.count)
    first_lane = ("inner", "outer")[int(rng.integers(2))]
    lanes = [first_lane if i % 2 == 0 else other_lane(first_lane) for i in range(config.count)]
    return [(place(track, arc0 + a, lane), lane) for a, lane in zip(arcs, lanes, strict=True)]


def bot_places(
    count: int, min_gap: float, track: Track, arc0: float
) -> list[tuple[Placement, str]]:
    """Bots spread evenly ahead of the start on alternating lanes (with their lane)."""
    spacing = track.length / (count + 1)
    if spacing < min_gap:
        raise ConfigError(
            f"{count} bots need {min_gap * (count + 1):.1f} m of track; "
            f"{track.name} is {track.length:.1f} m"
        )
    lanes = ["outer" if j % 2 == 0 else "inner" for j in range(count)]
    return [(place(track, arc0 + (j + 1) * spacing, lanes[j]), lanes[j]) for j in range(count)]


def other_lane(lane: str) -> str:
    """The lane across: ``outer`` for ``inner``, ``inner`` for anything else."""
    return "outer" if lane == "inner" else "inner"


def respawn_place(
    track: Track, arc: float, offset: float, obstacle: tuple[float, str] | None = None
) -> Placement:
    """Where a penalised car comes back: the lane centre nearest its last lateral offset at
    its last arc length, or 1 m behind the obstacle it hit, in the other lane."""
    if obstacle is not None:
        obstacle_arc, obstacle_lane = obstacle
        return place(track, obstacle_arc - RESPAWN_BEHIND_OBSTACLE_M, other_lane(obstacle_lane))
    arr = np.array([arc])
    inner = float(track.lane_offset(arr, "inner")[0])
    outer = float(track.lane_offset(arr, "outer")[0])
    lane = "inner" if abs(offset - inner) <= abs(offset - outer) else "outer"
    return place(track, arc, lane)
