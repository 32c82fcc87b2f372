"""The fast camera renderer: raster contents, geometry, PyBullet agreement.

Its speed is measured by ``benchmarks/camera_frame.py``, not here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from arena.camera import (
    BORDER_GRAY,
    CENTER_GRAY,
    GRASS_GRAY,
    LIGHT,
    ROAD_GRAY,
    SKY_GRAY,
    Box3D,
    CameraRenderer,
    TrackRaster,
    add_box_to_pybullet,
    add_track_to_pybullet,
    render_pybullet,
)
from arena.sensors_spec import CameraSpec
from tracks.io import read_track
from tracks.track import Track


def oval(a: float = 3.0, b: float = 2.0, width: float = 0.76, n: int = 120) -> Track:
    """A counter-clockwise elliptical loop."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    center = np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
    tangent = np.stack([-a * np.sin(t), b * np.cos(t)], axis=1)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    left, right = center + 0.5 * width * normal, center - 0.5 * width * normal
    return Track.from_arrays("oval", *(np.vstack([arr, arr[:1]]) for arr in (center, left, right)))


@pytest.fixture(scope="module")
def track() -> Track:
    return oval()


@pytest.fixture(scope="module")
def renderer(track: Track) -> CameraRenderer:
    return CameraRenderer(track)


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def test_raster_paints_road_borders_centre_line_and_grass(track: Track) -> None:
    raster = TrackRaster(track)
    pos, heading = track.pose_at(np.linspace(0.0, track.length, 40, endpoint=False))
    normal = np.stack([-np.sin(heading), np.cos(heading)], axis=1)
    assert np.all(raster.sample(pos + 0.2 * normal) == ROAD_GRAY)
    assert np.all(raster.sample(track.left[:-1]) == BORDER_GRAY)
    assert np.all(raster.sample(track.right[:-1]) == BORDER_GRAY)
    assert np.all(raster.sample(pos + 0.6 * normal) == GRASS_GRAY)
    assert np.all(raster.sample([[100.0, 100.0], [0.0, 0.0]]) == GRASS_GRAY)
    along, _ = track.pose_at(np.linspace(0.0, track.length, 2000, endpoint=False))
    dashed = np.mean(raster.sample(along) == CENTER_GRAY)
    assert 0.4 < dashed < 0.6


def test_render_shape_sky_and_ground(renderer: CameraRenderer, track: Track) -> None:
    (x, y), yaw = track.pose_at(1.0, lane=0.19)  # mid-way between centre line and border
    image = renderer.render(float(x), float(y), float(yaw))
    assert image.shape == (120, 160) and image.dtype == np.uint8
    assert np.all(image[0] == SKY_GRAY)
    assert image[-1, 80] == ROAD_GRAY  # the lane 0.23 m ahead: no line within 0.15 m of it
    assert np.array_equal(image, renderer.render(float(x), float(y), float(yaw)))
    stereo = renderer.render_stereo(float(x), float(y), float(yaw))
    assert stereo.shape == (120, 160, 2) and stereo.dtype == np.uint8
    assert not np.array_equal(stereo[..., 0], stereo[..., 1])


def test_horizon_and_field_of_view_match_the_spec() -> None:
    spec = CameraSpec()
    assert spec.vfov_deg == pytest.approx(50.82, abs=0.01)
    assert 2 * math.degrees(math.atan(0.5 * spec.width / spec.focal)) == pytest.approx(64.7)


def test_box_in_front_shows_its_lit_front_face(renderer: CameraRenderer) -> None:
    """A box dead ahead, square to the camera, shows its -x face just above the centre."""
    box = Box3D(x=1.09 + 0.5, y=0.0, yaw=0.0, length=1.0, width=1.0, height=0.3, gray=200)
    image = renderer.render(0.0, 0.0, 0.0, [box])
    front = LIGHT.face_grays(0.0, 200)[1]
    assert np.all(image[30, 60:100] == front)
    behind = Box3D(x=-2.0, y=0.0, yaw=0.0, length=0.4, width=0.2, height=0.2, gray=10)
    assert np.array_equal(renderer.render(0.0, 0.0, 0.0, [behind]), renderer.render(0.0, 0.0, 0.0))


def _scene_boxes(track: Track, s: float, rng: np.random.Generator) -> list[Box3D]:
    """Boxes around arc length ``s``: cars ahead, one occluding another, a low one, one beside."""
    boxes = []
    for ahead, lane, length, width, height in (
        (0.9, 0.15, 0.4, 0.2, 0.15),
        (1.6, 0.05, 0.4, 0.2, 0.15),
        (0.45, -0.15, 0.25, 0.25, 0.05),
        (0.05, -0.3, 0.5, 0.2, 0.2),
    ):
        (bx, by), _ = track.pose_at(s + ahead, lane=lane)
        gray = int(rng.integers(40, 230))
        yaw = float(rng.uniform(-np.pi, np.pi))
        boxes.append(Box3D(float(bx), float(by), yaw, length, width, height, gray))
    return boxes


def _agreement(track: Track, stereo_too: bool) -> tuple[float, float]:
    """Render random poses with both renderers; return (mean |diff|, share within 2 levels)."""
    rng = np.random.default_rng(7)
    renderer = CameraRenderer(track)
    client = p.connect(p.DIRECT)
    try:
        add_track_to_pybullet(client, renderer.raster)
        diffs = []
        for s in rng.uniform(0.0, track.length, 4):
            boxes = _scene_boxes(track, float(s), rng)
            ids = [add_box_to_pybullet(client, box) for box in boxes]
            (x, y), heading = track.pose_at(float(s), lane=float(rng.uniform(-0.2, 0.2)))
            pose = (float(x), float(y), float(heading) + float(rng.uniform(-0.5, 0.5)))
            pairs = [(renderer.render(*pose, boxes), 0.0)]
            if stereo_too:
                both = renderer.render_stereo(*pose, boxes)
                half = 0.5 * renderer.spec.stereo_baseline
                pairs += [(both[..., 0], half), (both[..., 1], -half)]
            for fast, lateral in pairs:
                ref = render_pybullet(client, renderer.spec, *pose, lateral=lateral)
                diffs.append(np.abs(fast.astype(int) - ref.astype(int)))
            for body in ids:
                p.removeBody(body, physicsClientId=client)
    finally:
        p.disconnect(client)
    d = np.stack(diffs)
    return float(d.mean()), float(np.mean(d <= 2))


def test_fast_renderer_matches_pybullet_on_an_oval() -> None:
    """The fast renderer against TinyRenderer on the same scene (mono and both stereo eyes).

    Scene: the track raster as a textured ground mesh plus four boxes per pose (cars
    ahead, one hiding another, a low box showing its top, one beside the camera that
    crosses the image edge). PyBullet lights with the same directional light (ambient
    0.5, diffuse 0.63, no specular, no shadows), and the fast renderer samples pixels
    where TinyRenderer does (pixel corners), so the two agree pixel for pixel.
    Tolerance: mean absolute difference <= 0.5 gray levels and >= 99.5 % of pixels
    within 2 levels. With PyBullet 3.2.7 the images are identical: mean 0.000, 100.0 % within 2
    (also on reinvent_base, 18 frames with boxes).
    """
    mad, within = _agreement(oval(), stereo_too=True)
    assert mad <= 0.5
    assert within >= 0.995


@pytest.mark.realdata
def test_fast_renderer_matches_pybullet_on_reinvent_base(shared_tracks: Path) -> None:
    """Same check on a real DeepRacer track (mono); same tolerance, measured 0.000 / 100 %."""
    mad, within = _agreement(read_track(shared_tracks / "reinvent_base.npy"), stereo_too=False)
    assert mad <= 0.5
    assert within >= 0.995


def test_boxes_in_view_change_the_frame(renderer: CameraRenderer, track: Track) -> None:
    """The scene ``benchmarks/camera_frame.py`` times: two boxes ahead show in the frame."""
    s = 1.0
    (x, y), yaw = track.pose_at(s)
    boxes = _scene_boxes(track, s, np.random.default_rng(0))[:2]
    pose = (float(x), float(y), float(yaw))
    assert not np.array_equal(renderer.render(*pose, boxes), renderer.render(*pose))
