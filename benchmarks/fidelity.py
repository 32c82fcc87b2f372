"""How close the car is to DeepRacer's: its step responses beside simapp's, and its laps
beside the DeepRacer leaderboards.

Two tables:

* **step responses**: :func:`arena.calibration.calibrate` drives the car (launch at full
  command, braking to the slowest command, a step to full lock) and each figure stands
  beside the one derived from deepracer-simapp v5.3.3b's files (``SIMAPP``: how each is
  derived is written there; none was measured in Gazebo);
* **laps**: on every 2022 track in the shared DeepRacer data whose leaderboard the
  script can name, the racing line's limit lap (what ``slipstream tracks raceline``
  reports), the pure-pursuit driver's best lap on that line (``--seeds`` 3-lap time
  trials, the median), and the leaderboard's best lap. A leaderboard is matched to the
  tracks released at most two days before it opened; of two boards opened together, the
  one with more racers raced the Open track and the other the Pro one.

Run::

    .venv/bin/python benchmarks/fidelity.py            # about 3 minutes on 2 cores
    .venv/bin/python benchmarks/fidelity.py --data ../shared/deepracer-data --seeds 1
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import re
import statistics
import tempfile
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

from harness import ROOT, ResultTable, add_record_option, write

DATA = ROOT.parent / "shared" / "deepracer-data"
LAPS = 3
SPACE = "continuous:-30:30:0.5:4"
GRAVITY = 9.81
SIMAPP_GRIP = 0.5 * GRAVITY
"""Drive and braking, m/s^2: the 10 N m wheel torque is far past the tyres' mu 0.5."""
SIMAPP_TOP = 100.0 * 0.036
"""The wheel joints' 100 rad/s limit on the 0.036 m rolling radius."""
SIMAPP_TAU = 0.5
"""The steering's time constant: the hinge PID's d / p (0.5 / 1.0) on its ~2.6e-4 kg m^2."""
SIMAPP = {
    "speed 0.5 s after a full command (m/s)": min(SIMAPP_GRIP * 0.5, SIMAPP_TOP),
    "speed 1 s after a full command (m/s)": min(SIMAPP_GRIP * 1.0, SIMAPP_TOP),
    "top speed on a 4 m/s command (m/s)": SIMAPP_TOP,
    "braking from top speed to 1 m/s (s)": (SIMAPP_TOP - 1.0) / SIMAPP_GRIP,
    "steering 0.5 s after a step to full lock (deg)": 30.0 * (1.0 - math.exp(-0.5 / SIMAPP_TAU)),
    "steering time constant (s)": SIMAPP_TAU,
}
RELEASED_BEFORE = timedelta(days=2)


@dataclass(frozen=True)
class Board:
    """One leaderboard's winner: its name, when it opened, how many raced, the best lap."""

    name: str
    launch: datetime
    racers: int
    best_lap: float


def _time(text: str) -> datetime:
    return datetime.fromisoformat(text.replace("Z", "+00:00"))


def read_boards(data: Path) -> list[Board]:
    """The rank-1 row of every 3-lap leaderboard in ``leaderboards_summary.csv``."""
    boards = []
    with (data / "leaderboards_summary.csv").open(newline="") as handle:
        for row in csv.DictReader(handle):
            if row["rank"] == "1" and row["lap_count"] == "3" and row["best_lap_ms"]:
                best = float(row["best_lap_ms"]) / 1000.0
                boards.append(
                    Board(row["name"].strip(), _time(row["launch"]), int(row["participants"]), best)
                )
    return boards


def read_releases(data: Path) -> dict[str, datetime]:
    """Track id (file stem without direction) -> release time, from the tracks' README."""
    releases = {}
    pattern = re.compile(r"track/(\w+)/track-resources.*?\*(\d{4}-\d\d-\d\dT[\d:]+Z)\*")
    for line in (data / "tracks" / "SOURCE_README.md").read_text().splitlines():
        found = pattern.search(line)
        if found:
            releases[found.group(1)] = _time(found.group(2))
    return releases


def match(boards: list[Board], releases: dict[str, datetime], year: int) -> dict[str, Board]:
    """Track id -> the leaderboard raced on it, for tracks released in ``year``."""
    matched: dict[str, Board] = {}
    for launch in sorted({b.launch for b in boards}):
        opened = sorted((b for b in boards if b.launch == launch), key=lambda b: b.racers)
        fresh = sorted(
            track
            for track, released in releases.items()
            if released.year == year and launch - RELEASED_BEFORE <= released <= launch
        )
        pro = [t for t in fresh if t.endswith("_pro")]
        open_ = [t for t in fresh if t.endswith("_open")]
        if len(opened) == 2 and len(pro) == 1 and len(open_) == 1:
            matched[pro[0]], matched[open_[0]] = opened
        elif len(opened) == 1 and len(fresh) == 1:
            matched[fresh[0]] = opened[0]
    return matched


def step_table() -> ResultTable:
    """The car's measured step responses beside simapp's derived ones."""
    from arena.calibration import calibrate
    from arena.car_spec import DEFAULT_CAR

    car = calibrate()
    lock = DEFAULT_CAR.max_steering_deg
    ours = {
        "speed 0.5 s after a full command (m/s)": car.launch.at(0.5),
        "speed 1 s after a full command (m/s)": car.launch.at(1.0),
        "top speed on a 4 m/s command (m/s)": car.top_speed,
        "braking from top speed to 1 m/s (s)": car.braking.time_to(1.0),
        "steering 0.5 s after a step to full lock (deg)": car.steering.at(0.5),
        "steering time constant (s)": car.steering_time_constant,
    }
    table = ResultTable(
        "the car's step responses: Slipstream (measured) beside simapp (derived)",
        ("response", "simapp (derived)", "Slipstream", "Slipstream / simapp"),
    )
    for name, theirs in SIMAPP.items():
        table.add_row(name, f"{theirs:.2f}", f"{ours[name]:.2f}", f"{ours[name] / theirs:.2f}")
    table.notes.append(
        f"calibrated limits: top {car.top_speed:.2f} m/s, drive {car.max_accel:.2f} and "
        f"braking {car.max_brake:.2f} m/s^2, lateral {car.cornering.max_lateral_accel:.2f} "
        f"m/s^2 at most, steering lag {car.steering_time_constant:.2f} s to 63% of a "
        f"{lock:g} deg step"
    )
    return table


def lap_table(data: Path, seeds: int) -> ResultTable:
    """Limit lap, pursuit driver and leaderboard best on every matched 2022 track."""
    import arena
    from agents.action_spaces import parse_action_space_spec
    from arena.pursuit import PurePursuitPolicy, racing_line_for
    from arena.race import run_race
    from tracks.catalog import import_track

    space = parse_action_space_spec(SPACE)
    boards = match(read_boards(data), read_releases(data), 2022)
    table = ResultTable(
        f"laps on the 2022 DeepRacer tracks: limit, pursuit driver ({seeds} seeds, median "
        f"best of {LAPS} laps), leaderboard winner",
        (
            "track",
            "leaderboard",
            "limit lap (s)",
            "driver (s)",
            "driver / limit",
            "driver off-tracks",
            "leaderboard best (s)",
            "leaderboard / limit",
        ),
        "ll" + "r" * 6,
    )
    for track_id, board in sorted(boards.items(), key=lambda item: item[1].launch):
        track = import_track(data / "tracks" / f"{track_id}.npy", overwrite=True)
        limit = racing_line_for(track).lap_time
        best, off = [], 0
        for seed in range(seeds):
            config = arena.make_config(
                track=track.name,
                race_type="time_trial",
                action_space=space,
                laps=LAPS,
                seed=seed,
                time_limit_s=LAPS * 4 * limit,
                sensors=("sector_lidar",),
            )
            car = run_race(config, {"car0": PurePursuitPolicy(track, space)}, record_trace=False)
            result = car.car("car0")
            best.append(result.best_lap if result.best_lap is not None else math.inf)
            off += result.off_track_count
        driver = statistics.median(best)
        table.add_row(
            track_id,
            f"{board.name} ({board.racers} racers)",
            f"{limit:.2f}",
            f"{driver:.2f}",
            f"{driver / limit:.3f}",
            str(off),
            f"{board.best_lap:.2f}",
            f"{board.best_lap / limit:.3f}",
        )
    table.notes.append(
        "Leaderboard laps count while any wheel is on the road; the racing line keeps the "
        "whole car 5 cm inside it."
    )
    return table


def main() -> None:
    """Print both tables (and record them, unless --no-record)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the shared DeepRacer data")
    parser.add_argument("--seeds", type=int, default=2, help="seeded time trials per track")
    add_record_option(parser)
    args = parser.parse_args()
    if not (args.data / "leaderboards_summary.csv").is_file():
        parser.error(f"no leaderboards_summary.csv in {args.data}")
    write(step_table(), args.record)
    with tempfile.TemporaryDirectory() as home:
        os.environ["SLIPSTREAM_HOME"] = home  # the imported tracks go here, then away
        write(lap_table(args.data, args.seeds), args.record)


if __name__ == "__main__":
    main()
