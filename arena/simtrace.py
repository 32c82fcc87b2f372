"""DeepRacer's simtrace CSV: one row per step, read by deepracer-utils and log notebooks."""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

SIMTRACE_COLUMNS = (
    "episode",
    "steps",
    "X",
    "Y",
    "yaw",
    "steer",
    "throttle",
    "action",
    "reward",
    "done",
    "all_wheels_on_track",
    "progress",
    "closest_waypoint",
    "track_len",
    "tstamp",
    "episode_status",
    "pause_duration",
    "obstacle_crash_counter",
    "wall_clock",
)


def race_rows(result, car: str, episode: int = 0, wall_clock: float = 0.0) -> list[dict[str, Any]]:
    """Simtrace rows of one car of a :class:`arena.race.RaceResult`."""
    columns = result.trace[car]
    track_len = _track_length(result)
    dt = result.config.control_dt
    rows = []
    n = len(columns["t"])
    paused = 0.0
    crashes = 0
    for i in range(n):
        status = columns["status"][i]
        paused += dt if status == "pause" else 0.0
        crashes += status == "crashed"
        rows.append(
            {
                "episode": episode,
                "steps": i + 1,
                "X": columns["x"][i],
                "Y": columns["y"][i],
                "yaw": math.degrees(columns["yaw"][i]),
                "steer": columns["steer"][i],
                "throttle": columns["throttle"][i],
                "action": _action(columns["action"][i]),
                "reward": columns["reward"][i],
                "done": i == n - 1,
                "all_wheels_on_track": columns["all_wheels_on_track"][i],
                "progress": columns["progress"][i],
                "closest_waypoint": columns["closest_waypoint"][i],
                "track_len": track_len,
                "tstamp": columns["t"][i],
                "episode_status": status,
                "pause_duration": paused,
                "obstacle_crash_counter": crashes,
                "wall_clock": wall_clock,
            }
        )
    return rows


def _track_length(result) -> float:
    from arena.env import resolve_track

    return resolve_track(result.config)[0].length


def _action(value: Any) -> Any:
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:.4f}" for v in value) + "]"
    return value


def write_simtrace(path: str | Path, rows: Iterable[dict[str, Any]]) -> Path:
    """Write simtrace rows (dicts keyed by :data:`SIMTRACE_COLUMNS`) as CSV."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=SIMTRACE_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow(row)
    return path
