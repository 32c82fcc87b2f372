"""``slipstream demo``: what a newcomer sees first.

For now it shows the built-in tracks with their physical-limit lap times, draws one with
its racing line, and races the built-in bot driver on it; the whole league (server,
scheduler, workers, leaderboards) joins it as those parts land.
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table


def run_demo(out: str | Path) -> None:
    """Print the built-in tracks and their yardstick lap times, write pictures to ``out``."""
    from tracks.catalog import builtin_names, get_track
    from tracks.plot import plot_track
    from tracks.raceline import CarLimits, centerline_profile, compute_racing_line

    console = Console()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    limits = CarLimits()
    table = Table(title="Slipstream built-in tracks (physical-limit lap: the yardstick)")
    for column in ("track", "name", "length m", "width m", "limit lap s", "centre-line lap s"):
        table.add_column(column, justify="left" if column in ("track", "name") else "right")
    lines = {}
    with console.status("computing racing lines..."):
        for name in builtin_names():
            track = get_track(name)
            line = compute_racing_line(track, limits)
            centre = centerline_profile(track, limits)
            lines[name] = (track, line)
            table.add_row(
                track.display_name,
                name,
                f"{track.length:.2f}",
                f"{track.width:.2f}",
                f"{line.lap_time:.2f}",
                f"{centre.lap_time:.2f}",
            )
    console.print(table)
    console.print(
        f"car limits: top speed {limits.max_speed} m/s, grip {limits.max_lateral_accel:.2f} "
        f"m/s², accel {limits.max_accel} m/s², brake {limits.max_brake} m/s²"
    )
    first = builtin_names()[0]
    track, line = lines[first]
    png = plot_track(track, out / f"{first}.png", racing_line=line)
    console.print(f"wrote {png}")
