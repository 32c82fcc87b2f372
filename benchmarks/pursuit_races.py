"""The passing pursuit driver (the imitation teacher) in seeded races: how fast, how clean.

Races :class:`arena.pursuit.PassingPursuitPolicy` with the races' actuation noise and
start jitter (``arena.config.SeedVariation``; training has neither), ``--seeds`` seeded
3-lap races per case, and prints one table: time trial on ``beginner_loop``, object
avoidance on ``slipstream_speedway`` (6 random boxes), head to bot on ``beginner_loop``
(the default bots) and, with ``--rival MODEL.zip``, head to model against that model
(the driver takes the model's slot on odd seeds; the grid is drawn per seed) on
``--rival-track``, the track the model learned (default ``beginner_loop``, the sample
models'). Columns: the driver's off-tracks and collisions over all races, the median
best lap and its ratio to the physical-limit lap, and against the rival its wins (also
split by which car started in front, with the driver's mean margin at the finish in the
races it started behind, as ``race_quality.py`` does) and the rival's own off-tracks and
collisions. One process, no training.

Run::

    .venv/bin/python benchmarks/pursuit_races.py --seeds 10
    .venv/bin/python benchmarks/pursuit_races.py --seeds 20 \
        --rival league/demo_models/sample-time-trial.zip
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from harness import ResultTable, add_record_option, write
from race_quality import StartSplit  # this folder's: the scripts run from it

import arena
from agents.action_spaces import parse_action_space_spec
from agents.selfplay import opponent_policy, read_policy_graph
from arena.pursuit import PassingPursuitPolicy, racing_line_for
from arena.race import RaceResult, run_race
from tracks.catalog import TrackNotFoundError, get_track

SPACE = "continuous:-30:30:0.5:4"
LAPS = 3
CASES = (  # (race type, track)
    ("time_trial", "beginner_loop"),
    ("object_avoidance", "slipstream_speedway"),
    ("head_to_bot", "beginner_loop"),
)


def race(race_type: str, track: str, seed: int, rival: bytes | None = None) -> RaceResult:
    """One seeded race of the driver (``car0`` on even seeds), alone or against ``rival``."""
    space = parse_action_space_spec(SPACE)
    config = arena.make_config(
        track=track,
        race_type=race_type,
        action_space=space,
        laps=LAPS,
        seed=seed,
        time_limit_s=60,
        num_cars=None if rival is None else 2,
        sensors=("camera",) if rival is not None else ("sector_lidar",),  # the rival's eyes
    )
    driver = PassingPursuitPolicy(get_track(track), space)
    if rival is None:
        return run_race(config, {"car0": driver}, record_trace=False)
    me, other = driver_slots(seed)
    policies = {me: driver, other: opponent_policy(rival, discrete=False, name="rival")}
    return run_race(config, policies, record_trace=False)


def driver_slots(seed: int) -> tuple[str, str]:
    """``(the driver's car, the rival's)`` in the race of ``seed``."""
    return ("car0", "car1") if seed % 2 == 0 else ("car1", "car0")


def row(race_type: str, track: str, seeds: int, rival: bytes | None = None) -> list[str]:
    """One table row: ``seeds`` races of one case."""
    course = get_track(track)
    incidents = rival_incidents = wins = 0
    split = StartSplit()
    best = []
    for seed in range(seeds):
        result = race(race_type, track, seed, rival)
        me, other = driver_slots(seed) if rival is not None else ("car0", "")
        car = result.car(me)
        incidents += car.off_track_count + car.crash_count
        best.append(car.best_lap if car.best_lap is not None else float("inf"))
        if rival is not None:
            opponent = result.car(other)
            rival_incidents += opponent.off_track_count + opponent.crash_count
            wins += split.add(result, me, other)
    median = statistics.median(best)
    limit = racing_line_for(course).lap_time  # the line the driver follows
    against = ["-"] * 5
    if rival is not None:
        margin = split.behind_margin()
        against = [f"{wins / seeds:.0%}", split.cell(True), split.cell(False)]
        against += ["-" if margin is None else f"{margin:+.2f}", str(rival_incidents)]
    return [
        race_type,
        track,
        str(seeds),
        str(incidents),
        f"{median:.2f}",
        f"{median / limit:.2f}",
    ] + against


def main() -> None:
    """Race every case and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10, help="seeded races per case")
    parser.add_argument("--rival", type=Path, help="a submission zip to race head to model")
    parser.add_argument(
        "--rival-track", default="beginner_loop", help="the head-to-model track (the rival's)"
    )
    add_record_option(parser)
    args = parser.parse_args()
    try:
        get_track(args.rival_track)
    except TrackNotFoundError as error:
        parser.error(str(error))
    columns = (
        "race type",
        "track",
        "races",
        "off-tracks + collisions",
        "median best lap (s)",
        "/ limit",
        "wins vs rival",
        "wins from ahead",
        "wins from behind",
        "margin from behind (s)",
        "rival's off-tracks + collisions",
    )
    title = f"passing pursuit driver, {LAPS}-lap seeded races ({SPACE})"
    table = ResultTable(title, columns, "ll" + "r" * (len(columns) - 2))
    for race_type, track in CASES:
        table.add_row(*row(race_type, track, args.seeds))
    if args.rival is not None:
        rival = read_policy_graph(args.rival)
        table.add_row(*row("head_to_model", args.rival_track, args.seeds, rival))
    write(table, args.record)


if __name__ == "__main__":
    main()
