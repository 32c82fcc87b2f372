"""The lidar: ranges from PyBullet bodies, own-body exclusion, noise, sector views, speed."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from arena.lidar import (
    Lidar,
    clip_lidar,
    discretized_sector_lidar,
    lidar_reach,
    sector_lidar,
)
from arena.sensors_spec import LIDAR_CLIP, LIDAR_MAX_RANGE, SENSOR_NAMES, LidarConfig


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
    p.createMultiBody(0.0, plane, physicsClientId=cid)
    yield cid
    p.disconnect(cid)


def add_box(client: int, x: float, y: float, yaw: float, half=(0.1, 0.1, 0.1)) -> int:
    """A static box standing on the ground."""
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=client)
    return p.createMultiBody(
        0.0,
        shape,
        basePosition=[x, y, half[2]],
        baseOrientation=p.getQuaternionFromEuler([0.0, 0.0, yaw]),
        physicsClientId=client,
    )


def add_car(client: int, x: float, y: float, yaw: float) -> int:
    """A car-like multibody: a box chassis and four cylinder wheels on hinge links."""
    chassis = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=[0.2, 0.1, 0.04], physicsClientId=client
    )
    wheel = p.createCollisionShape(
        p.GEOM_CYLINDER, radius=0.05, height=0.04, physicsClientId=client
    )
    axle = p.getQuaternionFromEuler([math.pi / 2, 0.0, 0.0])
    corners = [
        [0.15, 0.12, -0.03],
        [0.15, -0.12, -0.03],
        [-0.15, 0.12, -0.03],
        [-0.15, -0.12, -0.03],
    ]
    return p.createMultiBody(
        5.0,
        chassis,
        -1,
        [x, y, 0.08],
        p.getQuaternionFromEuler([0.0, 0.0, yaw]),
        linkMasses=[0.2] * 4,
        linkCollisionShapeIndices=[wheel] * 4,
        linkVisualShapeIndices=[-1] * 4,
        linkPositions=corners,
        linkOrientations=[axle] * 4,
        linkInertialFramePositions=[[0.0, 0.0, 0.0]] * 4,
        linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * 4,
        linkParentIndices=[0] * 4,
        linkJointTypes=[p.JOINT_REVOLUTE] * 4,
        linkJointAxis=[[0.0, 0.0, 1.0]] * 4,
        physicsClientId=client,
    )


def test_beam_layout() -> None:
    lidar = Lidar(client=0)
    assert lidar.beam_angles.shape == (64,)
    assert lidar.beam_angles[0] == pytest.approx(-math.radians(150))
    assert lidar.beam_angles[-1] == pytest.approx(math.radians(150))
    assert np.all(np.diff(lidar.beam_angles) > 0)


def test_flat_ground_alone_is_never_hit(client: int) -> None:
    ranges = Lidar(client).scan(0.3, -0.2, 1.0)
    assert ranges.dtype == np.float32 and ranges.shape == (64,)
    assert np.all(ranges == 12.0)


@pytest.mark.parametrize(
    ("beam", "distance", "yaw"), [(31, 1.0, 0.0), (5, 0.4, 2.0), (60, 3.7, -1.2)]
)
def test_box_is_seen_by_the_right_beam_at_its_distance(
    client: int, beam: int, distance: float, yaw: float
) -> None:
    """A box whose near face is ``distance`` from the mount, square to one beam."""
    lidar = Lidar(client, mount_forward=0.1, mount_height=0.07)
    x, y = 1.0, -2.0
    mount = np.array([x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw)])
    bearing = yaw + lidar.beam_angles[beam]
    center = mount + (distance + 0.1) * np.array([math.cos(bearing), math.sin(bearing)])
    add_box(client, float(center[0]), float(center[1]), bearing)
    ranges = lidar.scan(x, y, yaw)
    assert ranges[beam] == pytest.approx(distance, abs=0.01)
    assert int(np.argmin(ranges)) == beam
    far = np.abs(np.arange(64) - beam) > 4
    assert np.all(ranges[far] == 12.0)


def test_close_hits_clip_to_min_range(client: int) -> None:
    lidar = Lidar(client)
    add_box(client, 0.15, 0.0, 0.0)
    assert lidar.scan(0.0, 0.0, 0.0).min() == pytest.approx(0.15)


def test_own_body_is_excluded(client: int) -> None:
    car = add_car(client, 0.0, 0.0, 0.3)
    lidar = Lidar(client)
    seen_self = lidar.scan(0.0, 0.0, 0.3)
    assert np.sum(seen_self < 0.3) > 5
    assert np.all(lidar.scan(0.0, 0.0, 0.3, exclude=[car]) == 12.0)
    other = add_car(client, 0.0, 1.0, 0.0)
    ranges = lidar.scan(0.0, 0.0, 0.3, exclude=[car])
    left = int(np.argmin(np.abs(lidar.beam_angles + 0.3 - math.pi / 2)))
    assert ranges[left] == pytest.approx(1.0 - 0.1, abs=0.02)
    assert np.all(ranges[np.abs(np.arange(64) - left) > 8] == 12.0)
    assert other != car


def test_noise_only_with_rng(client: int) -> None:
    add_box(client, 2.1, 0.0, 0.0, half=(0.1, 2.0, 0.2))
    lidar = Lidar(client)
    clean = lidar.scan(0.0, 0.0, 0.0)
    assert np.array_equal(clean, lidar.scan(0.0, 0.0, 0.0))
    noisy = np.stack([lidar.scan(0.0, 0.0, 0.0, rng=np.random.default_rng(i)) for i in range(200)])
    hit = clean < 12.0
    assert hit.sum() > 10
    assert np.all(noisy[:, ~hit] == 12.0)
    assert np.std(noisy[:, hit] - clean[hit]) == pytest.approx(0.01, rel=0.1)
    again = lidar.scan(0.0, 0.0, 0.0, rng=np.random.default_rng(3))
    assert np.array_equal(again, noisy[3])


def covering_circle(client: int, body: int) -> tuple[float, float, float]:
    """``x, y, radius`` of a circle around a body's whole axis-aligned bounding box."""
    links = range(-1, p.getNumJoints(body, physicsClientId=client))
    boxes = [p.getAABB(body, link, physicsClientId=client) for link in links]
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    centre = 0.5 * (lo + hi)
    return centre[0], centre[1], 0.5 * math.hypot(hi[0] - lo[0], hi[1] - lo[1])


def place(client: int, body: int, x: float, y: float, yaw: float) -> None:
    """Move a body to ``(x, y)`` facing ``yaw``, at its height."""
    height = p.getBasePositionAndOrientation(body, physicsClientId=client)[0][2]
    quat = p.getQuaternionFromEuler([0.0, 0.0, yaw])
    p.resetBasePositionAndOrientation(body, [x, y, height], quat, physicsClientId=client)


def views(ranges: np.ndarray, lidar: Lidar) -> list[np.ndarray]:
    """What policies see of a scan: every lidar kind."""
    angles = lidar.beam_angles
    return [
        clip_lidar(ranges),
        sector_lidar(ranges, angles),
        discretized_sector_lidar(ranges, angles),
    ]


def test_culled_scans_look_the_same_as_full_scans(client: int) -> None:
    """Casting only the beams aimed at nearby bodies changes no lidar view, in 300 scenes."""
    rng = np.random.default_rng(7)
    own = add_car(client, 0.0, 0.0, 0.0)
    others = [add_car(client, 0.0, 0.0, 0.0) for _ in range(3)]
    boxes = [add_box(client, 0.0, 0.0, 0.0, half=(0.08, 0.12, 0.1)) for _ in range(2)]
    lidar = Lidar(client)
    reach = lidar_reach(SENSOR_NAMES, LidarConfig())
    hits = culled_beams = 0
    for _ in range(300):
        for body in others + boxes:
            x, y = rng.uniform(-1.8, 1.8, 2)
            place(client, body, x, y, rng.uniform(-math.pi, math.pi))
        x, y, yaw = rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-math.pi, math.pi)
        place(client, own, x, y, yaw)
        targets = np.array([covering_circle(client, body) for body in others + boxes])
        full = lidar.scan(x, y, yaw, exclude=[own])
        culled = lidar.scan(x, y, yaw, exclude=[own], reach=reach, targets=targets)
        for seen_full, seen_culled in zip(views(full, lidar), views(culled, lidar), strict=True):
            assert np.array_equal(seen_full, seen_culled)
        hits += int((full < LIDAR_CLIP).sum())
        culled_beams += int((culled == LIDAR_MAX_RANGE).sum())
    assert hits > 500  # the scenes put bodies within the policy's view
    assert culled_beams > hits


def test_lidar_reach_covers_each_view() -> None:
    """The reach is the farthest distance any of the car's lidar views distinguishes."""
    config = LidarConfig(clipping_dist=3.0)
    assert lidar_reach(("lidar",), config) == pytest.approx(LIDAR_CLIP + 0.1)
    assert lidar_reach(("sector_lidar",), config) == pytest.approx(0.6)
    assert lidar_reach(("discretized_sector_lidar",), config) == pytest.approx(3.1)
    assert lidar_reach(("camera",), config) == LIDAR_MAX_RANGE
    assert lidar_reach(("discretized_sector_lidar",), LidarConfig(clipping_dist=12.0)) == 12.0


def test_clip_lidar() -> None:
    out = clip_lidar(np.array([0.0, 0.15, 0.5, 1.0, 12.0]))
    assert out.dtype == np.float32
    assert np.allclose(out, [0.15, 0.15, 0.5, 1.0, 1.0])


ANGLES = np.linspace(-math.radians(150), math.radians(150), 64)


def test_sector_lidar() -> None:
    ranges = np.full(64, 12.0)
    assert np.array_equal(sector_lidar(ranges, ANGLES), np.zeros(8, dtype=np.float32))
    ranges[0] = 0.3  # rightmost beam: sector 0
    ranges[17] = 0.49  # sector 2 (beams 16-23)
    ranges[40] = 0.5  # not below the threshold
    ranges[63] = 0.1  # leftmost beam: sector 7
    out = sector_lidar(ranges, ANGLES)
    assert out.dtype == np.float32
    assert out.tolist() == [1, 0, 1, 0, 0, 0, 0, 1]
    assert sector_lidar(ranges, ANGLES, num_sectors=4, threshold=0.2).tolist() == [0, 0, 0, 1]


def test_discretized_sector_lidar() -> None:
    ranges = np.full(64, 12.0)
    ranges[3] = 0.3  # sector 0, bin floor(0.3 / 0.25) = 1
    ranges[5] = 0.9  # same sector, farther: the minimum counts
    ranges[8:16] = 1.99  # sector 1, last bin
    ranges[16:24] = 2.0  # sector 2: at the clip distance, nothing
    ranges[63] = 0.0  # sector 7, first bin
    out = discretized_sector_lidar(ranges, ANGLES)
    assert out.shape == (64,) and out.dtype == np.float32
    grid = out.reshape(8, 8)
    assert np.flatnonzero(grid[0]).tolist() == [1]
    assert np.flatnonzero(grid[1]).tolist() == [7]
    assert grid[2:7].sum() == 0
    assert np.flatnonzero(grid[7]).tolist() == [0]
    small = discretized_sector_lidar(ranges, ANGLES, num_sectors=2, num_values=4, clip=1.0)
    assert small.reshape(2, 4).tolist() == [[0, 1, 0, 0], [1, 0, 0, 0]]


def test_sector_views_default_to_the_default_lidar_config() -> None:
    config = LidarConfig()
    ranges = np.linspace(0.2, 3.0, 64)
    assert np.array_equal(
        sector_lidar(ranges, ANGLES), sector_lidar(ranges, ANGLES, config.num_sectors)
    )
    explicit = discretized_sector_lidar(
        ranges,
        ANGLES,
        num_sectors=config.num_sectors,
        num_values=config.num_values_per_sector,
        clip=config.clipping_dist,
    )
    assert np.array_equal(discretized_sector_lidar(ranges, ANGLES), explicit)
