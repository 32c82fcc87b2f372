"""Top-down pictures of a race: the track drawn once, cars and obstacles on top."""

from __future__ import annotations

import math

import numpy as np

from arena.car_spec import DEFAULT_CAR, CarSpec
from tracks.track import Track

GRASS = np.array([70, 125, 70], dtype=np.uint8)
ROAD = np.array([62, 62, 66], dtype=np.uint8)
BORDER = np.array([235, 235, 235], dtype=np.uint8)
CENTER = np.array([220, 190, 60], dtype=np.uint8)
BOX = np.array([230, 150, 30], dtype=np.uint8)
BOT = np.array([25, 25, 25], dtype=np.uint8)


class TopDownRenderer:
    """Draws frames of ``width`` pixels (height follows the track's aspect ratio); cars
    (and bots) are drawn with the footprint of ``car``."""

    def __init__(
        self, track: Track, width: int = 640, margin: float = 0.5, car: CarSpec = DEFAULT_CAR
    ) -> None:
        self.car = car
        xmin, ymin, xmax, ymax = track.bounds
        self.origin = np.array([xmin - margin, ymax + margin])
        self.scale = width / (xmax - xmin + 2 * margin)
        height = int(math.ceil((ymax - ymin + 2 * margin) * self.scale))
        self.shape = (height, width)
        self.background = self._draw_track(track)

    def to_pixels(self, points: np.ndarray) -> np.ndarray:
        """World ``(P, 2)`` metres to ``(P, 2)`` pixel ``(col, row)`` coordinates."""
        pts = np.asarray(points, dtype=float)
        return np.stack(
            [(pts[:, 0] - self.origin[0]) * self.scale, (self.origin[1] - pts[:, 1]) * self.scale],
            axis=1,
        )

    def _pixel_centres(self) -> np.ndarray:
        rows, cols = np.indices(self.shape)
        x = self.origin[0] + (cols + 0.5) / self.scale
        y = self.origin[1] - (rows + 0.5) / self.scale
        return np.stack([x.ravel(), y.ravel()], axis=1)

    def _draw_track(self, track: Track) -> np.ndarray:
        image = np.empty((*self.shape, 3), dtype=np.uint8)
        image[:] = GRASS
        road = np.zeros(self.shape[0] * self.shape[1], dtype=bool)
        centres = self._pixel_centres()
        for start in range(0, len(centres), 65536):
            road[start : start + 65536] = track.contains(centres[start : start + 65536])
        image.reshape(-1, 3)[road] = ROAD
        for line in (track.left, track.right):
            self._stroke(image, line, BORDER, 2)
        dashes = track.pose_at(np.arange(0.0, track.length, 0.05))[0]
        keep = (np.arange(len(dashes)) // 3) % 2 == 0
        self._dots(image, dashes[keep], CENTER, 1)
        start = np.vstack([track.left[0], track.right[0]])
        self._stroke(image, start, BORDER, 3)
        return image

    def _stroke(self, image: np.ndarray, line: np.ndarray, color: np.ndarray, radius: int) -> None:
        seg = np.diff(line, axis=0)
        lengths = np.linalg.norm(seg, axis=1)
        pts = [line[:1]]
        step = 0.5 / self.scale
        for a, d, length in zip(line[:-1], seg, lengths, strict=True):
            n = max(int(length / step), 1)
            pts.append(a + np.outer(np.arange(1, n + 1) / n, d))
        self._dots(image, np.vstack(pts), color, radius)

    def _dots(self, image: np.ndarray, points: np.ndarray, color: np.ndarray, radius: int) -> None:
        pix = np.round(self.to_pixels(points)).astype(int)
        for dr in range(-radius + 1, radius):
            for dc in range(-radius + 1, radius):
                r = np.clip(pix[:, 1] + dr, 0, self.shape[0] - 1)
                c = np.clip(pix[:, 0] + dc, 0, self.shape[1] - 1)
                image[r, c] = color

    def _fill_box(
        self,
        image: np.ndarray,
        x: float,
        y: float,
        yaw: float,
        length: float,
        width: float,
        color: np.ndarray,
    ) -> None:
        half = 0.5 * math.hypot(length, width)
        lo = np.floor(self.to_pixels(np.array([[x - half, y + half]]))[0]).astype(int)
        hi = np.ceil(self.to_pixels(np.array([[x + half, y - half]]))[0]).astype(int)
        c0, r0 = np.maximum(lo, 0)
        c1, r1 = min(hi[0], self.shape[1]), min(hi[1], self.shape[0])
        if c0 >= c1 or r0 >= r1:
            return
        rows, cols = np.mgrid[r0:r1, c0:c1]
        px = self.origin[0] + (cols + 0.5) / self.scale - x
        py = self.origin[1] - (rows + 0.5) / self.scale - y
        along = px * math.cos(yaw) + py * math.sin(yaw)
        across = -px * math.sin(yaw) + py * math.cos(yaw)
        inside = (np.abs(along) <= length / 2) & (np.abs(across) <= width / 2)
        image[r0:r1, c0:c1][inside] = color

    def _fill_car(
        self, image: np.ndarray, x: float, y: float, yaw: float, color: np.ndarray
    ) -> tuple[float, float]:
        """Fill the footprint of a car whose origin is at ``(x, y)``; returns its centre."""
        ahead = self.car.centre_ahead
        cx, cy = x + ahead * math.cos(yaw), y + ahead * math.sin(yaw)
        self._fill_box(image, cx, cy, yaw, self.car.length, self.car.width, color)
        return cx, cy

    def frame(
        self,
        cars: list[tuple[tuple[float, float, float, float], tuple[float, ...]]],
        bots: list[tuple[float, float, float]] = (),
        obstacles: list[tuple[float, float, float, float, float]] = (),
    ) -> np.ndarray:
        """One RGB frame: ``cars`` as ``((x, y, yaw, speed), rgba)`` at the car origin
        (rear axle), ``bots`` as ``(x, y, yaw)``, ``obstacles`` as ``(x, y, yaw, l, w)``."""
        image = self.background.copy()
        for x, y, yaw, length, width in obstacles:
            self._fill_box(image, x, y, yaw, length, width, BOX)
        for x, y, yaw in bots:
            self._fill_car(image, x, y, yaw, BOT)
        for (x, y, yaw, _), rgba in cars:
            color = (np.array(rgba[:3]) * 255).astype(np.uint8)
            cx, cy = self._fill_car(image, x, y, yaw, color)
            nose = (cx + 0.13 * math.cos(yaw), cy + 0.13 * math.sin(yaw))
            self._fill_box(image, *nose, yaw, 0.06, 0.08, BORDER)
        return image
