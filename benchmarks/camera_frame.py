"""Camera frame time: the arena's own renderer, mono and stereo, with and without boxes.

Renders one pose on a built-in track ``--frames`` times per case (after a few warm-up
frames) and prints the median and p99 frame time. The boxes stand ahead of the camera
like other cars (cars ahead, a low box, one beside), so they are in view. Single thread.

Run: ``.venv/bin/python benchmarks/camera_frame.py [--frames N] [--track NAME]``
"""

from __future__ import annotations

import argparse
from functools import partial

import numpy as np
from harness import ResultTable, add_record_option, summary, time_calls, write

from arena.camera import Box3D, CameraRenderer
from tracks.catalog import get_track
from tracks.track import Track

WARMUP = 5
# (metres ahead, lane offset, length, width, height) of each box, nearest in view first.
BOXES = (
    (0.9, 0.15, 0.4, 0.2, 0.15),
    (1.6, 0.05, 0.4, 0.2, 0.15),
    (0.45, -0.15, 0.25, 0.25, 0.05),
    (0.05, -0.3, 0.5, 0.2, 0.2),
)


def scene_boxes(track: Track, s: float, count: int) -> list[Box3D]:
    """The first ``count`` boxes of :data:`BOXES` around arc length ``s``."""
    rng = np.random.default_rng(0)
    boxes = []
    for ahead, lane, length, width, height in BOXES[:count]:
        (bx, by), _ = track.pose_at(s + ahead, lane=lane)
        yaw = float(rng.uniform(-np.pi, np.pi))
        boxes.append(Box3D(float(bx), float(by), yaw, length, width, height, 120))
    return boxes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200, help="timed frames per case")
    parser.add_argument("--track", default="beginner_loop", help="built-in track")
    add_record_option(parser)
    args = parser.parse_args()
    track = get_track(args.track)
    renderer = CameraRenderer(track)
    s = 1.0
    (x, y), yaw = track.pose_at(s)
    pose = (float(x), float(y), float(yaw))
    table = ResultTable("Camera frame time", ("case", "median ms", "p99 ms", "frames/s"))
    for name, stereo, count in (
        ("mono, no boxes", False, 0),
        ("mono, 2 boxes", False, 2),
        ("mono, 4 boxes", False, 4),
        ("stereo, 2 boxes", True, 2),
    ):
        boxes = scene_boxes(track, s, count)
        draw = renderer.render_stereo if stereo else renderer.render
        times = summary(time_calls(partial(draw, *pose, boxes), args.frames, warmup=WARMUP))
        table.add_row(
            name, f"{1e3 * times.median:.3f}", f"{1e3 * times.p99:.3f}", f"{1 / times.median:.0f}"
        )
    table.notes.append(f"{args.track}, {args.frames} timed frames per case")
    write(table, args.record)


if __name__ == "__main__":
    main()
