"""Where things start: car grids, obstacle boxes, bot cars, and respawn poses."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.config import ConfigError, ObstacleConfig, RaceConfig, SeedVariation
from tracks.track import Track

GRID_GAP_M = 0.8
START_CLEAR_M = 1.5
RESPAWN_BEHIND_OBSTACLE_M = 1.0
# A respawned car is released only this far (footprint to footprint) from everything else,
# and respawn spots are tried this far apart going back.
RESPAWN_CLEARANCE_M = DEFAULT_CAR.length
RESPAWN_STEP_M = 0.2


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


def grid_slots(count: int, track: Track, arc0: float, front_lane: str = "inner") -> list[Placement]:
    """Starting slots, front first: the centre line for one car, else a staggered grid on
    alternating lanes (``front_lane`` first), each slot ``GRID_GAP_M`` behind the one before."""
    if count == 1:
        return [place(track, arc0, "center")]
    return [
        place(track, arc0 - i * GRID_GAP_M, front_lane if i % 2 == 0 else other_lane(front_lane))
        for i in range(count)
    ]


def car_grid(
    config: RaceConfig, track: Track, arc0: float, rng: np.random.Generator
) -> list[Placement]:
    """Each controlled car's starting place, in the config's car order.

    What the seed varies (``config.active_variation``) is drawn from ``rng``, always in
    the same order: the slot of each car (taken by name, so the order the cars are listed
    in does not matter) and the front lane when the grid is shuffled, then each slot's
    jitter along, across and in heading, uniform within the bounds. Unshuffled, the cars
    take the slots in the listed order.
    """
    variation = config.active_variation
    count = len(config.cars)
    slot_of = list(range(count))
    front_lane = "inner"
    if variation.shuffle_grid and count > 1:
        by_name = sorted(range(count), key=lambda i: config.cars[i].name)
        for car, slot in zip(by_name, rng.permutation(count), strict=True):
            slot_of[car] = int(slot)
        front_lane = ("inner", "outer")[int(rng.integers(2))]
    slots = grid_slots(count, track, arc0, front_lane)
    if variation.start_jitter_m > 0.0 or variation.start_jitter_deg > 0.0:
        slots = [jittered(track, slot, rng, variation) for slot in slots]
    return [slots[slot] for slot in slot_of]


def jittered(
    track: Track, slot: Placement, rng: np.random.Generator, variation: SeedVariation
) -> Placement:
    """``slot`` moved by up to ``start_jitter_m`` along and across the track and turned by
    up to ``start_jitter_deg``."""
    along, across, turn = rng.uniform(-1.0, 1.0, size=3)
    moved = place(
        track,
        slot.arc + along * variation.start_jitter_m,
        slot.offset + across * variation.start_jitter_m,
    )
    return replace(moved, yaw=moved.yaw + math.radians(turn * variation.start_jitter_deg))


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
    track: Track,
    arc: float,
    offset: float,
    obstacle: tuple[float, str] | None = None,
    taken: Sequence[np.ndarray] = (),
    clearance: float = RESPAWN_CLEARANCE_M,
) -> Placement:
    """Where a penalised car comes back: the first free spot, going back from its own spot.

    Its own spot is the lane centre nearest its last lateral offset at its last arc
    length, or 1 m behind the obstacle it hit, in the other lane. A spot is free when the
    car's footprint there is ``clearance`` or more from every footprint in ``taken``
    (corner arrays of the other cars, bots and boxes). The spots tried: that lane, the
    other lane, then ``RESPAWN_STEP_M`` further back each time, up to half the track (on
    a loop) or its start. If none is free, the one with the most room.
    """
    if obstacle is not None:
        obstacle_arc, obstacle_lane = obstacle
        start, lane = obstacle_arc - RESPAWN_BEHIND_OBSTACLE_M, other_lane(obstacle_lane)
    else:
        start, lane = arc, nearest_lane(track, arc, offset)
    best, most_room = None, -1.0
    for spot in _spots_behind(track, start, lane):
        footprint = car_footprint(spot)
        if is_clear(footprint, taken, clearance):
            return spot
        room = room_around(footprint, taken)
        if room > most_room:
            best, most_room = spot, room
    assert best is not None
    return best


def nearest_lane(track: Track, arc: float, offset: float) -> str:
    """The lane (``inner`` or ``outer``) whose centre is nearest ``offset`` at ``arc``."""
    arr = np.array([arc])
    inner = float(track.lane_offset(arr, "inner")[0])
    outer = float(track.lane_offset(arr, "outer")[0])
    return "inner" if abs(offset - inner) <= abs(offset - outer) else "outer"


def _spots_behind(track: Track, start: float, lane: str) -> Iterator[Placement]:
    """Both lanes' centres (``lane`` first) at ``start``, then each step further back."""
    reach = 0.5 * track.length if track.is_loop else float(track.wrap_arc_length(start))
    arcs = start - np.arange(0.0, reach + 1e-9, RESPAWN_STEP_M)
    lanes = track.lane_offset(arcs, lane), track.lane_offset(arcs, other_lane(lane))
    for arc, near, far in zip(arcs, *lanes, strict=True):
        yield place(track, arc, float(near))
        yield place(track, arc, float(far))


def car_footprint(spot: Placement, spec: CarSpec = DEFAULT_CAR) -> np.ndarray:
    """Corners ``(4, 2)`` of the footprint of a car whose origin stands at ``spot``."""
    cos, sin = math.cos(spot.yaw), math.sin(spot.yaw)
    centre = (spot.x + spec.centre_ahead * cos, spot.y + spec.centre_ahead * sin)
    return rectangle(centre, spot.yaw, spec.length, spec.width)


def rectangle(
    centre: tuple[float, float], yaw: float, length: float, width: float
) -> np.ndarray:
    """Corners ``(4, 2)``, in order, of a ``length`` x ``width`` rectangle turned by ``yaw``."""
    half_l, half_w = 0.5 * length, 0.5 * width
    local = np.array([[half_l, half_w], [-half_l, half_w], [-half_l, -half_w], [half_l, -half_w]])
    cos, sin = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[cos, sin], [-sin, cos]]) + centre


def _bounding_circle(polygon: np.ndarray) -> tuple[np.ndarray, float]:
    centre = polygon.mean(axis=0)
    return centre, float(np.linalg.norm(polygon - centre, axis=1).max())


def is_clear(footprint: np.ndarray, others: Sequence[np.ndarray], clearance: float) -> bool:
    """Whether ``footprint`` is ``clearance`` or more from every one of ``others``.

    Cheaper than :func:`room_around` where most others are far: their bounding circles
    settle it without a polygon test.
    """
    centre, radius = _bounding_circle(footprint)
    for other in others:
        other_centre, other_radius = _bounding_circle(other)
        distance = float(np.linalg.norm(other_centre - centre))
        if distance - radius - other_radius >= clearance:
            continue
        if polygon_gap(footprint, other) < clearance:
            return False
    return True


def room_around(footprint: np.ndarray, others: Sequence[np.ndarray]) -> float:
    """The smallest gap (m) between ``footprint`` and any of ``others`` (inf if none)."""
    centre, radius = _bounding_circle(footprint)
    room = math.inf
    for other in others:
        other_centre, other_radius = _bounding_circle(other)
        if float(np.linalg.norm(other_centre - centre)) - radius - other_radius < room:
            room = min(room, polygon_gap(footprint, other))
    return room


def polygon_gap(a: np.ndarray, b: np.ndarray) -> float:
    """The shortest distance between two convex polygons (corners in order); 0 if they meet."""
    if _overlap(a, b):
        return 0.0
    return min(_corner_to_edge(a, b), _corner_to_edge(b, a))


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test over both polygons' edge normals."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([-edges[:, 1], edges[:, 0]], axis=1)
        on_a, on_b = a @ normals.T, b @ normals.T
        if np.any((on_a.max(axis=0) < on_b.min(axis=0)) | (on_b.max(axis=0) < on_a.min(axis=0))):
            return False
    return True


def _corner_to_edge(points: np.ndarray, poly: np.ndarray) -> float:
    """The shortest distance from any of ``points`` to any edge of ``poly``."""
    edges = np.roll(poly, -1, axis=0) - poly
    rel = points[:, None, :] - poly[None, :, :]
    along = np.clip((rel * edges).sum(axis=-1) / (edges * edges).sum(axis=-1), 0.0, 1.0)
    nearest = rel - along[..., None] * edges
    return float(np.sqrt((nearest * nearest).sum(axis=-1)).min())
