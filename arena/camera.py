"""The front camera: a fast ground-lookup renderer and a PyBullet reference renderer.

The track is flat, so a ground pixel's colour only depends on where its ray meets the
plane ``z = 0``. :class:`CameraRenderer` precomputes every pixel's ray once, rotates the
ground hits by the car's yaw and reads them from a :class:`TrackRaster`; other cars and
obstacles (:class:`Box3D`) are drawn on top by a per-pixel ray-box test with a depth
buffer. Faces are lit like PyBullet's TinyRenderer with :data:`LIGHT`, so
:func:`render_pybullet` (after :func:`add_track_to_pybullet`) gives the same picture.
The camera itself (size, field of view, mounting) is :class:`arena.sensors_spec.CameraSpec`.
"""

from __future__ import annotations

import itertools
import math
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pybullet as p

from arena.sensors_spec import DEFAULT_CAMERA, CameraSpec
from tracks.track import Track

GRASS_GRAY = 96
ROAD_GRAY = 56
BORDER_GRAY = 235
CENTER_GRAY = 190
SKY_GRAY = 205


@dataclass(frozen=True)
class Lighting:
    """A directional light, TinyRenderer style: ``gray * (ambient + diffuse * max(0, n.L))``.

    ``direction`` points towards the light (world frame, normalised on use). The default
    leaves the ground (normal +z) at full brightness and shades vertical faces 0.5-0.8.
    """

    direction: tuple[float, float, float] = (0.48, 0.36, 0.8)
    ambient: float = 0.5
    diffuse: float = 0.63

    def factor(self, nx: float, ny: float, nz: float) -> float:
        """Brightness factor of a surface with unit normal ``(nx, ny, nz)``."""
        lx, ly, lz = self.direction
        norm = math.sqrt(lx * lx + ly * ly + lz * lz)
        return self.ambient + self.diffuse * max(0.0, (nx * lx + ny * ly + nz * lz) / norm)

    def lit(self, gray: np.ndarray | int, factor: float) -> np.ndarray:
        """``gray`` scaled by ``factor`` the way TinyRenderer does (truncated, at most 255)."""
        return np.minimum(np.floor(np.asarray(gray) * factor), 255).astype(np.uint8)

    def face_grays(self, yaw: float, gray: int) -> tuple[int, ...]:
        """Lit gray of the faces +x, -x, +y, -y, +z, -z of a box turned by ``yaw``."""
        c, s = math.cos(yaw), math.sin(yaw)
        normals = ((c, s, 0.0), (-c, -s, 0.0), (-s, c, 0.0), (s, -c, 0.0), (0, 0, 1), (0, 0, -1))
        return tuple(min(math.floor(gray * self.factor(*n)), 255) for n in normals)


LIGHT = Lighting()
_BOX_CORNERS = np.array([(x, y, z) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.0, 1.0)])


@dataclass(frozen=True)
class Box3D:
    """An oriented box standing on the ground (another car, an obstacle); ``gray`` is its shade."""

    x: float
    y: float
    yaw: float
    length: float
    width: float
    height: float
    gray: int = 160


def _camera_axes(spec: CameraSpec, yaw: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward, right and up unit vectors of a camera on a car heading ``yaw``."""
    pitch = math.radians(spec.pitch_down_deg)
    c, s = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    return np.array([c * cp, s * cp, -sp]), np.array([s, -c, 0.0]), np.array([c * sp, s * sp, cp])


def _camera_position(
    spec: CameraSpec, x: float, y: float, yaw: float, lateral: float
) -> np.ndarray:
    """World position of a camera ``lateral`` metres left of the car's centre line."""
    c, s = math.cos(yaw), math.sin(yaw)
    fx, ly = spec.mount_forward, lateral
    return np.array([x + c * fx - s * ly, y + s * fx + c * ly, spec.mount_height])


class TrackRaster:
    """The flat ground as a grayscale picture: grass, road, white borders, dashed centre line.

    ``image[row, col]`` covers ``x0 + col * resolution`` (and ``y0 + row * resolution``)
    to one resolution step further; the outermost pixels are always grass.
    """

    def __init__(
        self,
        track: Track,
        resolution: float = 0.01,
        margin: float = 1.0,
        border_width: float = 0.05,
        center_width: float = 0.03,
        dash: tuple[float, float] = (0.15, 0.15),
    ) -> None:
        xmin, ymin, xmax, ymax = track.bounds
        self.resolution = float(resolution)
        self.x0 = xmin - margin
        self.y0 = ymin - margin
        nx = math.ceil((xmax + margin - self.x0) / resolution)
        ny = math.ceil((ymax + margin - self.y0) / resolution)
        road = self._fill_rings(track.road_rings, nx, ny)
        image = np.where(road, ROAD_GRAY, GRASS_GRAY).astype(np.uint8)
        self._stamp(image, track.waypoints, 0.5 * center_width, CENTER_GRAY, dash)
        for border in (track.left, track.right):
            self._stamp(image, border, 0.5 * border_width, BORDER_GRAY)
        image[[0, -1], :] = GRASS_GRAY
        image[:, [0, -1]] = GRASS_GRAY
        image.setflags(write=False)
        self.image = image

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the picture."""
        return self.image.shape

    def sample(self, points: np.ndarray) -> np.ndarray:
        """Gray levels at world points ``(P, 2)`` (grass outside the picture)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        ny, nx = self.image.shape
        col = np.clip((pts[:, 0] - self.x0) / self.resolution, 0, nx - 1).astype(np.intp)
        row = np.clip((pts[:, 1] - self.y0) / self.resolution, 0, ny - 1).astype(np.intp)
        return self.image[row, col]

    def _centers(self, n: int, origin: float) -> np.ndarray:
        return origin + (np.arange(n) + 0.5) * self.resolution

    def _fill_rings(self, rings: list[np.ndarray], nx: int, ny: int) -> np.ndarray:
        """Even-odd scanline fill of the region bounded by closed rings."""
        a = np.vstack(rings)
        b = np.vstack([np.roll(r, -1, axis=0) for r in rings])
        ys = self._centers(ny, self.y0)[:, None]
        straddles = (a[None, :, 1] > ys) != (b[None, :, 1] > ys)
        rows, edges = np.nonzero(straddles)
        ay, by = a[edges, 1], b[edges, 1]
        x_at = a[edges, 0] + (ys[rows, 0] - ay) * (b[edges, 0] - a[edges, 0]) / (by - ay)
        first_col = np.clip(np.ceil((x_at - self.x0) / self.resolution - 0.5), 0, nx)
        toggles = np.zeros((ny, nx + 1), dtype=np.int32)
        np.add.at(toggles, (rows, first_col.astype(np.intp)), 1)
        return (np.cumsum(toggles, axis=1)[:, :nx] % 2) == 1

    def _stamp(
        self,
        image: np.ndarray,
        line: np.ndarray,
        half_width: float,
        gray: int,
        dash: tuple[float, float] | None = None,
    ) -> None:
        """Paint pixels within ``half_width`` of a polyline (dashed: on/off lengths)."""
        ny, nx = image.shape
        res = self.resolution
        arc = 0.0
        for a, b in itertools.pairwise(line):
            seg = b - a
            length = float(np.hypot(*seg))
            lo = np.minimum(a, b) - half_width
            hi = np.maximum(a, b) + half_width
            c0, c1 = (np.clip([lo[0], hi[0]], self.x0, None) - self.x0) / res
            r0, r1 = (np.clip([lo[1], hi[1]], self.y0, None) - self.y0) / res
            cols = np.arange(int(c0), min(int(c1) + 1, nx))
            rows = np.arange(int(r0), min(int(r1) + 1, ny))
            if length == 0.0 or cols.size == 0 or rows.size == 0:
                continue
            px = self.x0 + (cols[None, :] + 0.5) * res - a[0]
            py = self.y0 + (rows[:, None] + 0.5) * res - a[1]
            t = np.clip((px * seg[0] + py * seg[1]) / length**2, 0.0, 1.0)
            near = np.hypot(px - t * seg[0], py - t * seg[1]) <= half_width
            if dash is not None:
                near &= np.mod(arc + t * length, dash[0] + dash[1]) < dash[0]
            image[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1][near] = gray
            arc += length


class _Rays:
    """Per-pixel rays of one camera in the car frame (car at the origin, heading +x).

    Pixel ``(row, col)`` is sampled where TinyRenderer samples it (at a pixel corner:
    ``col - width/2`` right and ``row + 1 - height/2`` down of the optical axis, in
    pixels), so both renderers agree pixel for pixel.
    """

    def __init__(self, spec: CameraSpec, lateral: float, resolution: float) -> None:
        forward, right, up = _camera_axes(spec, 0.0)
        f = spec.focal
        u = (np.arange(spec.width) - 0.5 * spec.width) / f
        v = (np.arange(spec.height) + 1.0 - 0.5 * spec.height) / f
        dirs = forward + u[None, :, None] * right - v[:, None, None] * up
        self.dx, self.dy, self.dz = (dirs[..., k].astype(np.float32) for k in range(3))
        self.origin = _camera_position(spec, 0.0, 0.0, 0.0, lateral)
        flat = dirs.reshape(-1, 3)
        with np.errstate(divide="ignore"):
            depth = np.where(flat[:, 2] < 0.0, spec.mount_height / -flat[:, 2], np.inf)
        self.ground = np.flatnonzero(depth <= spec.far)
        hit = self.origin[:2] + depth[self.ground, None] * flat[self.ground, :2]
        self.gx, self.gy = (hit[:, k].astype(np.float32) / resolution for k in range(2))


class CameraRenderer:
    """Fast camera images of a flat track with boxes on it (no PyBullet involved)."""

    def __init__(
        self,
        track: Track,
        spec: CameraSpec = DEFAULT_CAMERA,
        raster: TrackRaster | None = None,
        lighting: Lighting = LIGHT,
    ) -> None:
        self.spec = spec
        self.lighting = lighting
        self.raster = raster if raster is not None else TrackRaster(track)
        self._lit = lighting.lit(self.raster.image, lighting.factor(0.0, 0.0, 1.0)).ravel()
        res = self.raster.resolution
        half = 0.5 * spec.stereo_baseline
        self._mono = _Rays(spec, 0.0, res)
        self._stereo = (_Rays(spec, half, res), _Rays(spec, -half, res))

    def render(self, x: float, y: float, yaw: float, boxes: Sequence[Box3D] = ()) -> np.ndarray:
        """``(height, width)`` uint8 image from the camera of a car at ``(x, y, yaw)``."""
        return self._render(self._mono, x, y, yaw, boxes)

    def render_stereo(
        self, x: float, y: float, yaw: float, boxes: Sequence[Box3D] = ()
    ) -> np.ndarray:
        """``(height, width, 2)`` uint8: left and right camera, ``stereo_baseline`` apart."""
        left, right = (self._render(rays, x, y, yaw, boxes) for rays in self._stereo)
        return np.stack([left, right], axis=-1)

    def _render(
        self, rays: _Rays, x: float, y: float, yaw: float, boxes: Sequence[Box3D]
    ) -> np.ndarray:
        spec, raster = self.spec, self.raster
        c, s = np.float32(math.cos(yaw)), np.float32(math.sin(yaw))
        ny, nx = raster.shape
        col = rays.gx * c - rays.gy * s + np.float32((x - raster.x0) / raster.resolution)
        row = rays.gx * s + rays.gy * c + np.float32((y - raster.y0) / raster.resolution)
        np.clip(col, 0, nx - 1, out=col)
        np.clip(row, 0, ny - 1, out=row)
        index = row.astype(np.intp) * nx + col.astype(np.intp)
        image = np.full(spec.width * spec.height, SKY_GRAY, dtype=np.uint8)
        image[rays.ground] = self._lit[index]
        image = image.reshape(spec.height, spec.width)
        if boxes:
            depth = np.full(image.shape, spec.far, dtype=np.float32)
            origin = _camera_position(spec, x, y, yaw, rays.origin[1])
            axes = np.array(_camera_axes(spec, yaw))
            for box in boxes:
                window = self._box_window(origin, axes, box)
                if window is not None:
                    self._draw_box(image[window], depth[window], rays, window, origin, yaw, box)
        return image

    def _box_window(
        self, origin: np.ndarray, axes: np.ndarray, box: Box3D
    ) -> tuple[slice, slice] | None:
        """Pixel rows and columns that can show ``box`` (None when it is out of view)."""
        spec = self.spec
        c, s = math.cos(box.yaw), math.sin(box.yaw)
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        corners = (_BOX_CORNERS * (box.length, box.width, box.height)) @ rot
        cam = (corners + (box.x - origin[0], box.y - origin[1], -origin[2])) @ axes.T
        depth = cam[:, 0]
        if depth.max() <= spec.near or depth.min() > spec.far:
            return None
        if depth.min() <= spec.near:
            return slice(0, spec.height), slice(0, spec.width)
        cols = cam[:, 1] / depth * spec.focal + 0.5 * spec.width
        rows = -cam[:, 2] / depth * spec.focal + 0.5 * spec.height - 1.0
        c0, c1 = max(math.floor(cols.min()), 0), min(math.ceil(cols.max()) + 1, spec.width)
        r0, r1 = max(math.floor(rows.min()), 0), min(math.ceil(rows.max()) + 1, spec.height)
        if c0 >= c1 or r0 >= r1:
            return None
        return slice(r0, r1), slice(c0, c1)

    def _draw_box(
        self,
        image: np.ndarray,
        depth: np.ndarray,
        rays: _Rays,
        window: tuple[slice, slice],
        origin: np.ndarray,
        yaw: float,
        box: Box3D,
    ) -> None:
        """Ray-box (slab) test on a window of pixels; nearer surfaces win over ``depth``.

        The camera is outside the box, so each slab it is outside of has a fixed entry
        face (the one facing the camera); slabs it is inside of only bound the exit.
        """
        c, s = math.cos(box.yaw), math.sin(box.yaw)
        rel_x, rel_y = origin[0] - box.x, origin[1] - box.y
        rc, rs = np.float32(math.cos(yaw - box.yaw)), np.float32(math.sin(yaw - box.yaw))
        dx, dy = rays.dx[window], rays.dy[window]
        slabs = (
            (dx * rc - dy * rs, c * rel_x + s * rel_y, 0.5 * box.length),
            (dx * rs + dy * rc, -s * rel_x + c * rel_y, 0.5 * box.width),
            (rays.dz[window], origin[2] - 0.5 * box.height, 0.5 * box.height),
        )
        grays = self.lighting.face_grays(box.yaw, box.gray)
        entries: list[tuple[np.ndarray, int]] = []
        t_far = None
        with np.errstate(divide="ignore", invalid="ignore"):
            for axis, (d, o, half) in enumerate(slabs):
                t_lo, t_hi = (-half - o) / d, (half - o) / d
                if o < -half:
                    entries.append((t_lo, grays[2 * axis + 1]))
                    t_out = t_hi
                elif o > half:
                    entries.append((t_hi, grays[2 * axis]))
                    t_out = t_lo
                else:
                    t_out = np.maximum(t_lo, t_hi)
                t_far = t_out if t_far is None else np.minimum(t_far, t_out)
        if not entries:
            return
        t_near, gray = entries[0]
        for t_in, face_gray in entries[1:]:
            gray = np.where(t_in > t_near, face_gray, gray)
            t_near = np.maximum(t_near, t_in)
        hit = (t_near > 0.0) & (t_near <= t_far) & (t_near < depth)
        image[hit] = gray if np.isscalar(gray) else gray[hit]
        depth[hit] = t_near[hit]


def render_pybullet(
    client: int,
    spec: CameraSpec,
    x: float,
    y: float,
    yaw: float,
    lateral: float = 0.0,
    lighting: Lighting = LIGHT,
) -> np.ndarray:
    """Reference image from ``p.getCameraImage`` (TinyRenderer) with the same intrinsics.

    Lit with ``lighting`` (no specular term, no shadows); background pixels get the sky
    shade and colours become gray levels (ITU-R 601 luma), so the result is comparable
    with :meth:`CameraRenderer.render`.
    """
    eye = _camera_position(spec, x, y, yaw, lateral)
    forward, _, up = _camera_axes(spec, yaw)
    view = p.computeViewMatrix(eye.tolist(), (eye + forward).tolist(), up.tolist())
    proj = p.computeProjectionMatrixFOV(
        spec.vfov_deg, spec.width / spec.height, spec.near, spec.far
    )
    _, _, rgba, _, seg = p.getCameraImage(
        spec.width,
        spec.height,
        view,
        proj,
        lightDirection=list(lighting.direction),
        lightAmbientCoeff=lighting.ambient,
        lightDiffuseCoeff=lighting.diffuse,
        lightSpecularCoeff=0.0,
        shadow=0,
        renderer=p.ER_TINY_RENDERER,
        physicsClientId=client,
    )
    rgb = np.reshape(rgba, (spec.height, spec.width, 4))[..., :3].astype(np.float32)
    gray = np.rint(rgb @ np.array([0.299, 0.587, 0.114], dtype=np.float32)).astype(np.uint8)
    gray[np.reshape(seg, (spec.height, spec.width)) < 0] = SKY_GRAY
    return gray


def add_box_to_pybullet(client: int, box: Box3D) -> int:
    """A static PyBullet body for ``box`` (collision and visual shape); returns its id."""
    half = [0.5 * box.length, 0.5 * box.width, 0.5 * box.height]
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    vis = p.createVisualShape(
        p.GEOM_BOX,
        halfExtents=half,
        rgbaColor=[box.gray / 255.0] * 3 + [1.0],
        physicsClientId=client,
    )
    return p.createMultiBody(
        0.0,
        col,
        vis,
        basePosition=[box.x, box.y, 0.5 * box.height],
        baseOrientation=p.getQuaternionFromEuler([0.0, 0.0, box.yaw]),
        physicsClientId=client,
    )


def _ground_mesh(
    raster: TrackRaster, surround: float, cell: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, triangle indices and texture coordinates of the textured ground.

    A grid over the raster (``cell`` metres) plus a grass skirt ``surround`` metres wide
    whose texture coordinates all point at a (grass) corner texel.
    """
    ny, nx = raster.shape
    res = raster.resolution
    width, height = nx * res, ny * res
    xs = np.linspace(0.0, width, max(2, math.ceil(width / cell) + 1))
    ys = np.linspace(0.0, height, max(2, math.ceil(height / cell) + 1))
    gx, gy = np.meshgrid(xs, ys)
    verts = [np.stack([gx.ravel(), gy.ravel()], axis=1)]
    uvs = [np.stack([gx.ravel() / width, gy.ravel() / height], axis=1)]
    tris = []
    n_cols = len(xs)
    for j in range(len(ys) - 1):
        for i in range(n_cols - 1):
            k = j * n_cols + i
            tris += [(k, k + 1, k + n_cols + 1), (k, k + n_cols + 1, k + n_cols)]
    lo, hi = -surround, surround
    outer = [(lo, lo), (width + hi, lo), (width + hi, height + hi), (lo, height + hi)]
    inner = [(0.0, 0.0), (width, 0.0), (width, height), (0.0, height)]
    base = len(verts[0])
    verts.append(np.array(outer + inner, dtype=float))
    uvs.append(np.full((8, 2), 0.5 / max(nx, ny)))
    for q in range(4):
        o0, o1, i0, i1 = base + q, base + (q + 1) % 4, base + 4 + q, base + 4 + (q + 1) % 4
        tris += [(o0, o1, i1), (o0, i1, i0)]
    xy = np.vstack(verts) + [raster.x0, raster.y0]
    vertices = np.column_stack([xy, np.zeros(len(xy))])
    return vertices, np.array(tris, dtype=int), np.vstack(uvs)


def add_track_to_pybullet(
    client: int, raster: TrackRaster, surround: float = 40.0, cell: float = 0.5
) -> int:
    """Put the raster into a PyBullet scene as a textured ground mesh; returns its body id.

    The mesh lies at ``z = 0`` (a visual shape only: cars keep driving on their own
    plane) and is ringed by ``surround`` metres of grass (keep it beyond the camera's
    ``far``) so the horizon matches the fast renderer's.
    """
    vertices, triangles, uvs = _ground_mesh(raster, surround, cell)
    vis = p.createVisualShape(
        p.GEOM_MESH,
        vertices=vertices.tolist(),
        indices=triangles.ravel().tolist(),
        uvs=uvs.tolist(),
        normals=[[0.0, 0.0, 1.0]] * len(vertices),
        rgbaColor=[1.0, 1.0, 1.0, 1.0],
        physicsClientId=client,
    )
    body = p.createMultiBody(0.0, -1, vis, physicsClientId=client)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "track.png"
        # Texture v runs upwards (+y) while PNG rows run downwards: store the rows flipped.
        iio.imwrite(path, np.repeat(raster.image[::-1, :, None], 3, axis=-1))
        texture = p.loadTexture(str(path), physicsClientId=client)
    p.changeVisualShape(body, -1, textureUniqueId=texture, physicsClientId=client)
    return body
