"""Time trials alone: model files lap each track against the scripted teacher, seed by seed.

Each driver races alone in seeded time trials with the races' noise (``--laps`` laps, the
grid and noise of seeds ``--seeds``), the scripted teacher (the passing pursuit driver the
imitation recipes copy and PPO is anchored to) first. One table, a row per (track,
driver): the races finished, the mean lap (total time over the laps, off-track penalties
included) and the best lap, the off-tracks summed, and against the teacher race by race
(the same seed): in how many of the races both finished the driver was faster, and the
mean difference a lap with its standard error. The issue's stretch target reads the last
two: PPO after imitation laps faster than its teacher.

    .venv/bin/python benchmarks/time_trial_laps.py --model runs/tt_ppo/model/model.zip
    .venv/bin/python benchmarks/time_trial_laps.py --model A.zip --model B.zip --seeds 0-29
"""

from __future__ import annotations

import argparse
from pathlib import Path
from statistics import mean, stdev
from typing import Any

from h2h_gauntlet import ME, SCRIPTED_ME, _rules, real_width_tracks
from harness import ResultTable, add_record_option, write
from rich.progress import Progress

from arena.config import CarConfig, RaceConfig
from arena.pursuit import PassingPursuitPolicy
from arena.race import StepGuard, run_race
from league.jobs.evaluation import model_car
from submissions import ModelFault, load_policy
from tracks.catalog import get_track

TEACHER = "the teacher"


def seed_range(text: str) -> list[int]:
    """``"10-29"`` or ``"0,3,5"``: the seeds named (a range includes both ends)."""
    if "-" in text:
        first, last = (int(part) for part in text.split("-", 1))
        if last < first:
            raise argparse.ArgumentTypeError(f"seeds {text!r}: the range runs backwards")
        return list(range(first, last + 1))
    return [int(part) for part in text.split(",")]


def lap_times(
    driver: Any, car: CarConfig, track: str, laps: int, seeds: list[int], progress: Any
) -> tuple[dict[int, float | None], int, float | None]:
    """Each seed's mean lap (None: not finished), the off-tracks over all the races and
    the best single lap."""
    laps_by_seed: dict[int, float | None] = {}
    off_tracks, best_laps = 0, []
    for seed in seeds:
        config = RaceConfig.build(cars=[car], **_rules(track, laps, seed, "time_trial"))
        result = run_race(config, {ME: driver}, guard=StepGuard(faults=(ModelFault,))).car(ME)
        off_tracks += result.off_track_count
        laps_by_seed[seed] = None if result.total_time is None else result.total_time / laps
        best_laps += [] if result.best_lap is None else [result.best_lap]
        progress()
    return laps_by_seed, off_tracks, min(best_laps, default=None)


def against(mine: dict[int, float | None], teacher: dict[int, float | None]) -> list[str]:
    """Race by race against the teacher (the seeds both finished): the races the driver was
    faster in, and the mean difference a lap with its standard error."""
    diffs = [lap - teacher[s] for s, lap in mine.items() if lap and teacher.get(s)]
    if not diffs:
        return ["-", "-"]
    error = f" ± {stdev(diffs) / len(diffs) ** 0.5:.3f}" if len(diffs) > 1 else ""
    return [f"{sum(d < 0 for d in diffs)}/{len(diffs)}", f"{mean(diffs):+.3f}{error}"]


def main() -> None:
    """Parse options, race every driver alone on every track, write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, action="append", required=True)
    parser.add_argument("--tracks", default=",".join(real_width_tracks()))
    parser.add_argument("--seeds", type=seed_range, default=seed_range("0-19"))
    parser.add_argument("--laps", type=int, default=3)
    add_record_option(parser)
    args = parser.parse_args()
    models = []
    for path in args.model:
        policy = load_policy(path, non_finite="raise", name=f"car {ME}")
        models.append((str(path), policy, model_car(ME, policy.info.model_dump(mode="json"))))
    tracks = args.tracks.split(",")
    columns = ["track", "driver", "finished", "mean lap s", "best lap s", "off-tracks",
               "faster than the teacher", "s/lap against the teacher"]  # fmt: skip
    table = ResultTable(
        f"Time trials alone: {len(args.seeds)} seeded races of {args.laps} laps a driver",
        columns,
        "ll" + "r" * 6,
    )
    with Progress() as bar:
        task = bar.add_task("time trials", total=len(tracks) * (len(models) + 1) * len(args.seeds))
        for track in tracks:
            teacher_driver = PassingPursuitPolicy(get_track(track), SCRIPTED_ME.action_space)
            drivers = [(TEACHER, teacher_driver, SCRIPTED_ME), *models]
            teacher: dict[int, float | None] | None = None
            for name, driver, car in drivers:
                laps, off, best = lap_times(
                    driver, car, track, args.laps, args.seeds, lambda: bar.advance(task)
                )
                finished = [lap for lap in laps.values() if lap is not None]
                table.add_row(
                    track,
                    name,
                    f"{len(finished)}/{len(laps)}",
                    f"{mean(finished):.3f}" if finished else "-",
                    f"{best:.2f}" if best is not None else "-",
                    off,
                    *(["", ""] if teacher is None else against(laps, teacher)),
                )
                teacher = laps if teacher is None else teacher
    table.notes.append(
        "mean lap: total time / laps over the races finished, penalties included; the "
        "comparison pairs each seed's races that both finished"
    )
    write(table, args.record)


if __name__ == "__main__":
    main()
