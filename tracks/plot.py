"""Pictures of tracks: a matplotlib figure (PNG, SVG, PDF) and a tiny SVG thumbnail."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tracks.raceline import RacingLine
from tracks.track import Track


def _road_polygon(track: Track) -> np.ndarray:
    """Outline of the road surface: left border out, right border back."""
    return np.vstack([track.left, track.right[::-1]])


def plot_track(
    track: Track,
    path: str | Path,
    racing_line: RacingLine | None = None,
    title: str | None = None,
) -> Path:
    """Draw the track (and optionally a racing line coloured by speed) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    path = Path(path)
    fig, ax = plt.subplots(figsize=(8, 6), layout="constrained")
    road = _road_polygon(track)
    if track.is_loop:
        ax.fill(track.outer[:, 0], track.outer[:, 1], color="0.85", zorder=0)
        ax.fill(track.inner[:, 0], track.inner[:, 1], color="white", zorder=0)
    else:
        ax.fill(road[:, 0], road[:, 1], color="0.85", zorder=0)
    for border in (track.left, track.right):
        ax.plot(border[:, 0], border[:, 1], color="0.15", lw=1.2)
    ax.plot(track.waypoints[:, 0], track.waypoints[:, 1], "--", color="0.45", lw=0.8)
    ax.plot(
        [track.left[0, 0], track.right[0, 0]],
        [track.left[0, 1], track.right[0, 1]],
        color="tab:red",
        lw=2.5,
        label="start",
    )
    (pos,), (heading,) = track.pose_at(np.array([min(0.5, track.length / 4)]))
    arrow_len = max(0.6 * track.width, 0.3)
    ax.annotate(
        "",
        xy=pos + arrow_len * np.array([np.cos(heading), np.sin(heading)]),
        xytext=pos,
        arrowprops={"arrowstyle": "-|>", "color": "tab:red", "lw": 1.5},
    )
    if racing_line is not None:
        pts = racing_line.points
        segments = np.stack([pts[:-1], pts[1:]], axis=1)
        lines = LineCollection(segments, cmap="plasma", linewidths=2.0)
        lines.set_array(0.5 * (racing_line.speed[:-1] + racing_line.speed[1:]))
        ax.add_collection(lines)
        fig.colorbar(lines, ax=ax, label="speed (m/s)", shrink=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    heading_text = title or (
        f"{track.display_name} ({track.direction}): {track.length:.2f} m long, "
        f"{track.width:.2f} m wide"
    )
    if racing_line is not None and title is None:
        heading_text += f"\nphysical-limit lap {racing_line.lap_time:.2f} s"
    ax.set_title(heading_text)
    ax.legend(loc="best", fontsize="small")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def track_thumbnail_svg(track: Track, size: int = 120, padding: float = 0.05) -> str:
    """A small standalone SVG of the road outline (borders as one even-odd filled path)."""
    xmin, ymin, xmax, ymax = track.bounds
    span = max(xmax - xmin, ymax - ymin, 1e-9)
    scale = size * (1 - 2 * padding) / span
    off_x = (size - (xmax - xmin) * scale) / 2
    off_y = (size - (ymax - ymin) * scale) / 2

    def ring(points: np.ndarray) -> str:
        x = off_x + (points[:, 0] - xmin) * scale
        y = size - (off_y + (points[:, 1] - ymin) * scale)
        coords = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(x, y, strict=True))
        return f"M{coords}Z"

    rings = [track.left, track.right] if track.is_loop else [_road_polygon(track)]
    d = " ".join(ring(r) for r in rings)
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {size}" '
        f'width="{size}" height="{size}"><title>{_escape(track.display_name)}</title>'
        f'<path d="{d}" fill="#bbb" fill-rule="evenodd" stroke="#222" stroke-width="1"/></svg>'
    )


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
