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
    LIDAR_MOUNT_FORWARD,
    LIDAR_MOUNT_HEIGHT,
    LIDAR_NOISE_STD,
    SECTOR_THRESHOLD,
    LidarConfig,
)

_CLEARANCE = 1e-4
# The sector views default to DeepRacer's default ``lidar_config``.
_DEFAULT_VIEW = LidarConfig()
# Beyond what a lidar view distinguishes, a hit still matters if noise could pull it back
# in; ten standard deviations make that a 1e-23 event.
_NOISE_MARGIN = 10.0 * LIDAR_NOISE_STD


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
        self._first_beam = float(self.beam_angles[0])
        self._beam_step = 2.0 * half / (num_beams - 1) if num_beams > 1 else 1.0
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
        reach: float | None = None,
        targets: np.ndarray | None = None,
    ) -> np.ndarray:
        """Ranges ``(num_beams,)`` float32 in metres from the mount of a car at ``(x, y, yaw)``.

        ``max_range`` where nothing is hit; hits are clipped to ``[min_range, max_range]``.
        Bodies in ``exclude`` (the car itself) are invisible. With ``rng``, hits get
        Gaussian noise of ``noise_std`` metres; without, scans are deterministic.

        With ``targets``, ``(K, 3)`` ``x, y, radius`` circles covering every body the
        beams could hit, only the beams aimed at a circle that comes within ``reach`` of
        the mount are cast; the others read ``max_range``. For callers that look no
        farther than ``reach`` the scan is then the same, for less work (the noise is
        drawn for every beam, so ``rng`` advances the same either way).
        """
        return self.scan_many(
            np.array([[x, y, yaw]], dtype=float),
            [tuple(exclude)],
            rng=rng,
            noise_std=noise_std,
            reach=None if reach is None else [reach],
            targets=targets,
        )[0]

    def scan_many(
        self,
        poses: np.ndarray,
        excludes: Sequence[Sequence[int]],
        rng: np.random.Generator | None = None,
        noise_std: float = LIDAR_NOISE_STD,
        reach: Sequence[float] | None = None,
        targets: np.ndarray | None = None,
        visible: np.ndarray | None = None,
    ) -> np.ndarray:
        """:meth:`scan` for ``N`` cars at once, in one batch of rays: ``(N, num_beams)``.

        ``poses`` is ``(N, 3)`` ``x, y, yaw``; ``excludes[n]``, ``reach[n]`` are car
        ``n``'s; ``visible`` ``(N, K)`` says which ``targets`` car ``n`` may see (not its
        own circle). Each car's ranges are those :meth:`scan` gives it alone.
        """
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        num_cars, num_beams = len(poses), len(self.beam_angles)
        mounts = [
            (x + self.mount_forward * math.cos(yaw), y + self.mount_forward * math.sin(yaw), yaw)
            for x, y, yaw in poses.tolist()
        ]
        aimed = np.zeros((num_cars, num_beams), dtype=bool)
        if targets is None:
            aimed[:] = True
        else:
            circles = np.asarray(targets, dtype=float).reshape(-1, 3).tolist()
            sees = np.ones((num_cars, len(circles)), dtype=bool) if visible is None else visible
            for n, (mx, my, yaw) in enumerate(mounts):
                look = self.max_range if reach is None else min(float(reach[n]), self.max_range)
                for k, (tx, ty, radius) in enumerate(circles):
                    if sees[n, k]:
                        self._aim(aimed[n], tx - mx, ty - my, radius, yaw, look)
        ranges = np.full((num_cars, num_beams), self.max_range)
        hit = np.zeros((num_cars, num_beams), dtype=bool)
        car, beam = np.nonzero(aimed)
        if len(car):
            origins = np.array([(mx, my, self.mount_height) for mx, my, _ in mounts])
            yaw = poses[:, 2]
            starts = np.stack(
                [
                    self._start_distances(origins[n], yaw[n], tuple(excludes[n]))
                    for n in range(num_cars)
                ]
            )[car, beam]
            angles = self.beam_angles[beam] + yaw[car]
            dirs = np.zeros((len(angles), 3))
            np.cos(angles, out=dirs[:, 0])
            np.sin(angles, out=dirs[:, 1])
            fraction = self._cast(origins[car], dirs, starts, car, excludes)
            hit[car, beam] = fraction < 1.0
            ranges[car, beam] = starts + fraction * (self.max_range - starts)
        if rng is not None and noise_std > 0.0:
            noise = rng.normal(0.0, noise_std, ranges.shape)
            ranges = np.where(hit, ranges + noise, ranges)
        return np.clip(ranges, self.min_range, self.max_range).astype(np.float32)

    def _aim(
        self, row: np.ndarray, dx: float, dy: float, radius: float, yaw: float, look: float
    ) -> None:
        """Mark in ``row`` the beams that could meet a circle ``(dx, dy)`` from the mount.

        A ray meets a circle of radius ``r`` whose centre is ``d`` away at bearing ``b``
        exactly when its direction is within ``asin(r / d)`` of ``b``; the beam index
        window is rounded outwards. A circle beyond ``look`` is ignored; a mount inside
        a circle marks every beam.
        """
        dist = math.hypot(dx, dy)
        if dist - radius > look:
            return
        if dist <= radius:
            row[:] = True
            return
        half = math.asin(radius / dist)
        bearing = math.atan2(dy, dx) - yaw
        first, step = self._first_beam, self._beam_step
        for turn in (-2.0 * math.pi, 0.0, 2.0 * math.pi):
            lo = max(math.floor((bearing + turn - half - first) / step), 0)
            hi = min(math.ceil((bearing + turn + half - first) / step), len(row) - 1)
            if lo <= hi:
                row[lo : hi + 1] = True

    def _cast(
        self,
        origins: np.ndarray,
        dirs: np.ndarray,
        start: np.ndarray,
        car: np.ndarray,
        excludes: Sequence[Sequence[int]],
    ) -> np.ndarray:
        """Cast beams from ``start`` to ``max_range``; the hit fraction of each (1: miss).

        Beam ``i`` belongs to car ``car[i]``; its hits on ``excludes[car[i]]`` are misses.
        """
        begin = origins + dirs * start[:, None]
        end = origins + dirs * self.max_range
        results = p.rayTestBatch(begin, end, numThreads=1, physicsClientId=self.client)
        bodies, _, fractions, _, _ = zip(*results, strict=True)
        fraction = np.array(fractions)
        ids = np.array(bodies)
        excluded = [(body, n) for n, bodies_of_car in enumerate(excludes) for body in bodies_of_car]
        if excluded:
            # ``ignored[body, n]``: car n does not see body. A miss's id, -1, reads the
            # last row, which no body fills.
            rows = max(int(ids.max()), max(body for body, _ in excluded)) + 2
            ignored = np.zeros((rows, len(excludes)), dtype=bool)
            ignored[tuple(np.array(excluded).T)] = True
            fraction[ignored[ids, car]] = 1.0
        return fraction

    def _start_distances(
        self, origin: np.ndarray, yaw: float, exclude: tuple[int, ...]
    ) -> np.ndarray:
        """Where each beam leaves the excluded bodies, cached per set of bodies.

        The excluded body is the scanning car itself, rigid around its mount and driving
        on flat ground, so the exit distances along the (car-relative) beams do not
        change from scan to scan; they are measured once at the first scan.
        """
        if not exclude:
            return np.zeros(len(self.beam_angles))
        cached = self._exits.get(exclude)
        if cached is None:
            angles = self.beam_angles + yaw
            dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros(len(angles))], axis=1)
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


def lidar_reach(sensors: Sequence[str], config: LidarConfig) -> float:
    """How far a car's lidar views look: beyond it every range reads the same to them.

    ``lidar`` is clipped at ``LIDAR_CLIP``, ``sector_lidar`` thresholds at
    ``SECTOR_THRESHOLD`` and ``discretized_sector_lidar`` clips at ``clipping_dist``;
    a noise margin is added so that culling never changes an observation.
    """
    looks = {
        "lidar": LIDAR_CLIP,
        "sector_lidar": SECTOR_THRESHOLD,
        "discretized_sector_lidar": config.clipping_dist,
    }
    needed = [looks[name] for name in sensors if name in looks]
    if not needed:
        return LIDAR_MAX_RANGE
    return min(max(needed) + _NOISE_MARGIN, LIDAR_MAX_RANGE)


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
    num_sectors: int = _DEFAULT_VIEW.num_sectors,
    threshold: float = SECTOR_THRESHOLD,
) -> np.ndarray:
    """DeepRacer's SECTOR_LIDAR: ``(num_sectors,)`` float32, 1 where something is nearer than
    ``threshold`` in that sector (sectors ordered like the beams, right to left)."""
    minima = _sector_minima(ranges, beam_angles, num_sectors)
    return (minima < threshold).astype(np.float32)


def discretized_sector_lidar(
    ranges: np.ndarray,
    beam_angles: np.ndarray,
    num_sectors: int = _DEFAULT_VIEW.num_sectors,
    num_values: int = _DEFAULT_VIEW.num_values_per_sector,
    clip: float = _DEFAULT_VIEW.clipping_dist,
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
