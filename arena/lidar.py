"""The planar lidar (one ``p.rayTestBatch`` per scan) and the policy's views of its ranges.

Beams are cast horizontally at the mount height, so they never meet the flat ground.
Beams leave the car where it ends: the own body's collision shapes (the bodies in
``exclude``) are intersected with every beam first and the beam starts just beyond them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as p

from arena.sensors_spec import (
    LIDAR_BEAMS,
    LIDAR_CLIP,
    LIDAR_FOV_DEG,
    LIDAR_MAX_RANGE,
    LIDAR_MIN_RANGE,
    LIDAR_NOISE_STD,
    SECTOR_THRESHOLD,
)

LIDAR_MOUNT_FORWARD = 0.0
LIDAR_MOUNT_HEIGHT = 0.07
_CLEARANCE = 1e-4


@dataclass(frozen=True)
class _BodyShapes:
    """An excluded body's convex collision shapes as boxes in their links' frames.

    Part ``k`` spans ``+-half[k]`` around ``position[k]`` along the axes ``rotation[k]``
    of the inertial frame of its link: the base when ``frame_index[k]`` is 0, else link
    ``frame_links[frame_index[k] - 1]``. Links with shapes that have no simple bounds
    (meshes) are covered by their world AABB instead.
    """

    frame_links: tuple[int, ...]
    frame_index: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    half: np.ndarray
    aabb_links: tuple[int, ...]

    @classmethod
    def of(cls, client: int, body: int) -> _BodyShapes:
        """Read the collision shapes of ``body`` once."""
        links, positions, rotations, halves, aabb_links = [], [], [], [], []
        for link in range(-1, p.getNumJoints(body, physicsClientId=client)):
            for shape in p.getCollisionShapeData(body, link, physicsClientId=client):
                kind, dims = shape[2], shape[3]
                if kind == p.GEOM_PLANE:
                    continue
                if kind == p.GEOM_BOX:
                    half = [0.5 * dims[0], 0.5 * dims[1], 0.5 * dims[2]]
                elif kind == p.GEOM_SPHERE:
                    half = [dims[0]] * 3
                elif kind in (p.GEOM_CYLINDER, p.GEOM_CAPSULE):
                    cap = dims[1] if kind == p.GEOM_CAPSULE else 0.0
                    half = [dims[1], dims[1], 0.5 * dims[0] + cap]
                else:
                    aabb_links.append(link)
                    continue
                links.append(link)
                positions.append(shape[5])
                rotations.append(np.reshape(p.getMatrixFromQuaternion(shape[6]), (3, 3)))
                halves.append(half)
        frame_links = tuple(sorted(set(links) - {-1}))
        return cls(
            frame_links=frame_links,
            frame_index=np.array(
                [frame_links.index(i) + 1 if i >= 0 else 0 for i in links], dtype=int
            ),
            position=np.array(positions, dtype=float).reshape(-1, 3),
            rotation=np.array(rotations, dtype=float).reshape(-1, 3, 3),
            half=np.array(halves, dtype=float).reshape(-1, 3),
            aabb_links=tuple(sorted(set(aabb_links))),
        )

    def world_boxes(self, client: int, body: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centres ``(K, 3)``, rotations ``(K, 3, 3)`` and half extents of the parts now."""
        poses = [p.getBasePositionAndOrientation(body, physicsClientId=client)]
        if self.frame_links:
            states = p.getLinkStates(
                body, self.frame_links, computeForwardKinematics=True, physicsClientId=client
            )
            poses += [state[:2] for state in states]
        frame_pos = np.array([pose[0] for pose in poses])[self.frame_index]
        frame_rot = np.array([p.getMatrixFromQuaternion(pose[1]) for pose in poses])
        frame_rot = frame_rot.reshape(-1, 3, 3)[self.frame_index]
        centers = frame_pos + (frame_rot @ self.position[:, :, None])[:, :, 0]
        rotations = frame_rot @ self.rotation
        if not self.aabb_links:
            return centers, rotations, self.half
        boxes = np.array([p.getAABB(body, i, physicsClientId=client) for i in self.aabb_links])
        lo, hi = boxes[:, 0], boxes[:, 1]
        eye = np.broadcast_to(np.eye(3), (len(boxes), 3, 3))
        return (
            np.vstack([centers, 0.5 * (lo + hi)]),
            np.concatenate([rotations, eye]),
            np.vstack([self.half, 0.5 * (hi - lo)]),
        )


class Lidar:
    """A 2-D scanning lidar on a car: ``num_beams`` beams over ``fov_deg``, from right to left.

    The mount is ``mount_forward`` ahead of the car origin and ``mount_height`` above the
    ground; other cars are only seen if their collision shapes reach that height. The
    shapes of excluded bodies are read once per body id: after removing bodies or
    resetting the simulation, make a new ``Lidar``.
    """

    def __init__(
        self,
        client: int,
        num_beams: int = LIDAR_BEAMS,
        fov_deg: float = LIDAR_FOV_DEG,
        min_range: float = LIDAR_MIN_RANGE,
        max_range: float = LIDAR_MAX_RANGE,
        mount_forward: float = LIDAR_MOUNT_FORWARD,
        mount_height: float = LIDAR_MOUNT_HEIGHT,
    ) -> None:
        self.client = client
        self.min_range = float(min_range)
        self.max_range = float(max_range)
        self.mount_forward = float(mount_forward)
        self.mount_height = float(mount_height)
        half = 0.5 * math.radians(fov_deg)
        self.beam_angles = np.linspace(-half, half, num_beams)
        self.beam_angles.setflags(write=False)
        self._shapes: dict[int, _BodyShapes] = {}
        self._exits: dict[tuple[int, ...], np.ndarray] = {}

    def scan(
        self,
        x: float,
        y: float,
        yaw: float,
        exclude: Sequence[int] = (),
        rng: np.random.Generator | None = None,
        noise_std: float = LIDAR_NOISE_STD,
    ) -> np.ndarray:
        """Ranges ``(num_beams,)`` float32 in metres from the mount of a car at ``(x, y, yaw)``.

        ``max_range`` where nothing is hit; hits are clipped to ``[min_range, max_range]``.
        Bodies in ``exclude`` (the car itself) are invisible. With ``rng``, hits get
        Gaussian noise of ``noise_std`` metres; without, scans are deterministic.
        """
        angles = self.beam_angles + yaw
        dirs = np.zeros((len(angles), 3))
        dirs[:, 0] = np.cos(angles)
        dirs[:, 1] = np.sin(angles)
        origin = np.array(
            [
                x + self.mount_forward * math.cos(yaw),
                y + self.mount_forward * math.sin(yaw),
                self.mount_height,
            ]
        )
        start = self._start_distances(origin, dirs, tuple(exclude))
        starts = origin + dirs * start[:, None]
        ends = origin + dirs * self.max_range
        results = p.rayTestBatch(starts, ends, numThreads=1, physicsClientId=self.client)
        # A miss has fraction 1 (max_range); hits on excluded bodies count as misses.
        fraction = np.fromiter((1.0 if r[0] in exclude else r[2] for r in results), float)
        ranges = start + fraction * (self.max_range - start)
        if rng is not None and noise_std > 0.0:
            noise = rng.normal(0.0, noise_std, ranges.shape)
            ranges = np.where(fraction < 1.0, ranges + noise, ranges)
        return np.clip(ranges, self.min_range, self.max_range).astype(np.float32)

    def _start_distances(
        self, origin: np.ndarray, dirs: np.ndarray, exclude: tuple[int, ...]
    ) -> np.ndarray:
        """Where each beam leaves the excluded bodies, cached per set of bodies.

        The excluded body is the scanning car itself, rigid around its mount and driving
        on flat ground, so the exit distances along the (car-relative) beams do not
        change from scan to scan; they are measured once at the first scan.
        """
        if not exclude:
            return np.zeros(len(dirs))
        cached = self._exits.get(exclude)
        if cached is None:
            cached = self._exits[exclude] = self._own_body_exit(origin, dirs, exclude)
        return cached

    def _own_body_exit(
        self, origin: np.ndarray, dirs: np.ndarray, exclude: Sequence[int]
    ) -> np.ndarray:
        """Per beam, how far from ``origin`` the last excluded shape it crosses ends (or 0)."""
        boxes = []
        for body in exclude:
            shapes = self._shapes.get(body)
            if shapes is None:
                shapes = self._shapes[body] = _BodyShapes.of(self.client, body)
            boxes.append(shapes.world_boxes(self.client, body))
        centers, rotations, halves = (np.concatenate(parts) for parts in zip(*boxes, strict=True))
        if len(centers) == 0:
            return np.zeros(len(dirs))
        # Slab test in each box's frame: along an axis with inverse direction ``inv`` the
        # ray is inside the slab for ``t`` in ``-o * inv -+ half * |inv|``.
        local = dirs @ rotations
        local[local == 0.0] = 1e-12
        inv = 1.0 / local
        reach = halves[:, None, :] * np.abs(inv)
        mid = ((centers - origin)[:, None, :] @ rotations) * inv
        hi, lo = mid + reach, mid - reach
        t_far = np.minimum(np.minimum(hi[..., 0], hi[..., 1]), hi[..., 2])
        t_near = np.maximum(np.maximum(lo[..., 0], lo[..., 1]), lo[..., 2])
        t_far[~(t_near <= t_far)] = 0.0
        return np.maximum(t_far.max(axis=0) + _CLEARANCE, _CLEARANCE)


def clip_lidar(ranges: np.ndarray) -> np.ndarray:
    """The policy's lidar input: ranges clipped to ``[LIDAR_MIN_RANGE, LIDAR_CLIP]``, float32."""
    return np.clip(np.asarray(ranges, dtype=np.float32), LIDAR_MIN_RANGE, LIDAR_CLIP)


def _sector_minima(ranges: np.ndarray, beam_angles: np.ndarray, num_sectors: int) -> np.ndarray:
    """Minimum range per equal-angle sector, right to left (inf where a sector has no beam)."""
    angles = np.asarray(beam_angles, dtype=float)
    lo, hi = angles.min(), angles.max()
    span = hi - lo if hi > lo else 1.0
    sector = np.minimum(((angles - lo) / span * num_sectors).astype(int), num_sectors - 1)
    minima = np.full(num_sectors, np.inf)
    np.minimum.at(minima, sector, np.asarray(ranges, dtype=float))
    return minima


def sector_lidar(
    ranges: np.ndarray,
    beam_angles: np.ndarray,
    num_sectors: int = 8,
    threshold: float = SECTOR_THRESHOLD,
) -> np.ndarray:
    """DeepRacer's SECTOR_LIDAR: ``(num_sectors,)`` float32, 1 where something is nearer than
    ``threshold`` in that sector (sectors ordered like the beams, right to left)."""
    minima = _sector_minima(ranges, beam_angles, num_sectors)
    return (minima < threshold).astype(np.float32)


def discretized_sector_lidar(
    ranges: np.ndarray,
    beam_angles: np.ndarray,
    num_sectors: int = 8,
    num_values: int = 8,
    clip: float = 2.0,
) -> np.ndarray:
    """DeepRacer's DISCRETIZED_SECTOR_LIDAR: ``(num_sectors * num_values,)`` float32.

    Per sector, the minimum range falls into one of ``num_values`` equal bins over
    ``[0, clip)``; that bin is 1. A sector with nothing nearer than ``clip`` is all zeros.
    """
    minima = _sector_minima(ranges, beam_angles, num_sectors)
    bins = np.floor(np.minimum(minima, clip) / (clip / num_values)).astype(int)
    out = np.zeros((num_sectors, num_values + 1), dtype=np.float32)
    out[np.arange(num_sectors), bins] = 1.0
    return out[:, :num_values].ravel()
