"""Head-to-head gauntlet: one model file against a fixed field on real-width tracks.

For each track (default: the built-in tracks as wide as DeepRacer's, 1.07 m) the model
first laps alone (its solo lap: the mean over five time trials, penalties included), then
races two-car heats, ``--races`` seeded races per rival with the grid alternating (seeds
0, 1, ...; on odd seeds the model starts in front):

- the pure-pursuit driver (``arena.pursuit.PurePursuitPolicy``: the racing line, braking
  for its corners, no passing) with its speed profile scaled to 60, 80, 90 and 100% of the
  model's solo pace (its mean speed over the solo laps), at most to its own pace;
- each other model file of ``--field`` (default: the other sample models);
- the scripted teacher (the passing pursuit driver, the league's bot).

One table, a row per (track, rival): the model's wins from behind and from ahead, the
races started behind in which it got past the rival (at least one overtake), overtakes and
at-fault collisions per race (the model's, ``arena.racing_metrics``), where those contacts
came (:func:`contact_kinds`: in the standing start, running into the rival from behind,
or alongside it), and the seconds a lap it lost in the races it started behind, against
its solo laps (total time per lap minus the solo lap time; races it did not finish are
left out and counted). A last note sums the heats against the paced drivers below the
model's pace (60-90%) over every track, as the head-to-head target reads them: the share
of the races started behind in which the model got past, and its at-fault collisions a
race.

    .venv/bin/python benchmarks/h2h_gauntlet.py --model league/demo_models/sample-self-play.zip
    .venv/bin/python benchmarks/h2h_gauntlet.py --model M.zip --races 4 --laps 1  # quick
    .venv/bin/python benchmarks/h2h_gauntlet.py --teacher --field  # the teacher, no models
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from statistics import mean
from typing import Any

import numpy as np
from harness import ROOT, ResultTable, add_record_option, write
from rich.progress import Progress

from arena.actions import ContinuousActionSpace
from arena.config import CarConfig, RaceConfig, SeedVariation, resolve_track
from arena.pursuit import PassingPursuitPolicy, PurePursuitPolicy
from arena.race import RaceResult, StepGuard, run_race
from arena.rules import SIDE_BY_SIDE_M
from league.jobs.evaluation import model_car
from slipstream.race import rotated
from submissions import ModelFault, load_policy
from tracks.catalog import builtin_names, get_track
from tracks.track import Track

SAMPLES = ROOT / "league" / "demo_models"
PACES = (0.6, 0.8, 0.9, 1.0)
SLOWER = tuple(p for p in PACES if p < 1.0)
"""The paces of the slower cars the head-to-head target asks the model to pass."""
DEEPRACER_WIDTH_M = 1.067
ME, RIVAL = "model", "rival"
# A contact in a race's first seconds belongs to the standing start (both cars launching
# from the grid, 2 s: the teacher's START_FOLLOW_STEPS).
START_S = 2.0
CONTACT_KINDS = ("start", "rear", "side")
SCRIPTED_SPACE = ContinuousActionSpace()
"""The scripted drivers' action space (0.5-4 m/s): the paced racers' and the teacher's."""
SCRIPTED_ME = CarConfig(name=ME, action_space=SCRIPTED_SPACE)


@dataclass
class Heat:
    """One rival: a name for the table and how to build its driver on a track."""

    name: str
    car: CarConfig
    driver: Any


def _rules(track: str, laps: int, seed: int, race_type: str) -> dict[str, Any]:
    return {
        "track": track,
        "race_type": race_type,
        "laps": laps,
        "seed": seed,
        "time_limit_s": 60.0 * laps,
        "variation": SeedVariation(shuffle_grid=False),
    }


def real_width_tracks() -> list[str]:
    """The built-in tracks as wide as DeepRacer's (1.07 m)."""
    return [n for n in builtin_names() if get_track(n).width >= DEEPRACER_WIDTH_M - 0.01]


SOLO_RACES = 5


def solo_lap(model: Any, car: CarConfig, track: str, laps: int) -> float | None:
    """The model's mean lap time racing alone, penalties included, over the time trials of
    seeds 0-4 it finished (None: it finished none)."""
    totals = []
    for seed in range(SOLO_RACES):
        config = RaceConfig.build(cars=[car], **_rules(track, laps, seed, "time_trial"))
        result = run_race(config, {ME: model}, guard=StepGuard(faults=(ModelFault,)))
        totals += [] if result.car(ME).total_time is None else [result.car(ME).total_time]
    return mean(totals) / laps if totals else None


def model_heats(field: list[Path]) -> list[Heat]:
    """A heat per other model file, each loaded (and validated) once for every track."""
    heats = []
    for path in field:
        other = load_policy(path, non_finite="raise", name=f"car {RIVAL}")
        heats.append(Heat(path.stem, model_car(RIVAL, other.info.model_dump(mode="json")), other))
    return heats


def paced_name(share: float) -> str:
    """The heat name of the pursuit driver paced to ``share`` of the model's pace."""
    return f"pursuit {share:.0%}"


def rivals(track_name: str, pace: float, rival_pace: float, models: list[Heat]) -> list[Heat]:
    """The field on one track: the paced pursuit drivers (``rival_pace``: the pursuit
    driver's own, m/s), the other models, the teacher."""
    track = get_track(track_name)
    scripted = CarConfig(name=RIVAL, action_space=SCRIPTED_SPACE)
    space = scripted.action_space
    heats = [
        Heat(
            paced_name(p),
            scripted,
            PurePursuitPolicy(track, space, pace=min(1.0, p * pace / rival_pace)),
        )
        for p in PACES
    ]
    heats += models
    heats.append(Heat("teacher", scripted, PassingPursuitPolicy(track, space)))
    return heats


def field_on(
    track: str, model: Any, car: CarConfig, laps: int, models: list[Heat], notes: list[str]
) -> tuple[float | None, list[Heat]]:
    """The model's solo lap on ``track`` and its field there (:func:`rivals`, paced by that
    lap against the pursuit driver's own); what both laps were goes to ``notes``."""
    road = get_track(track)
    solo = solo_lap(model, car, track, laps)
    pace = road.length / solo if solo else 1.0
    notes.append(
        f"{track}: solo lap {solo:.2f} s ({pace:.2f} m/s)"
        if solo
        else f"{track}: the model did not finish alone; rivals paced at 1 m/s"
    )
    # the pursuit driver's own pace, in the paced racers' car (whatever the model's space)
    rival_lap = solo_lap(PurePursuitPolicy(road, SCRIPTED_SPACE), SCRIPTED_ME, track, laps)
    rival_pace = road.length / rival_lap if rival_lap else pace
    if rival_lap:
        notes.append(f"{track}: the pursuit driver alone {rival_lap:.2f} s a lap")
    return solo, rivals(track, pace, rival_pace, models)


def race_heat(model: Any, car: CarConfig, heat: Heat, track: str, laps: int, k: int) -> RaceResult:
    """Race ``k`` of a heat: seed ``k``, the model behind on even ``k``."""
    config = RaceConfig.build(cars=[heat.car, car], **_rules(track, laps, k, "head_to_model"))
    config = rotated(config, k, k)
    guard = StepGuard(faults=(ModelFault,))  # a rival model's faults retire it too
    return run_race(config, {ME: model, RIVAL: heat.driver}, guard=guard)


def _position_before(trace: dict[str, list], t: float) -> tuple[float, float]:
    """A car's ``(x, y)`` at its last trace row before simulated time ``t`` (the row of a
    contact's own step may already hold the car frozen or moved for its penalty)."""
    times = trace["t"]
    i = max(0, int(np.searchsorted(times, t - 1e-9)) - 1)
    return trace["x"][i], trace["y"][i]


def contact_kinds(result: RaceResult, track: Track) -> Counter[str]:
    """The model's at-fault contacts by where they came: ``start`` in the first
    :data:`START_S` of the race, ``rear`` running into the car from more than
    ``SIDE_BY_SIDE_M`` behind it (along the track, the step before), ``side`` closer."""
    kinds: Counter[str] = Counter()
    for event in result.events:
        if event["kind"] != "contact" or event["car"] != ME or not event["at_fault"]:
            continue
        if event["t"] < START_S:
            kinds["start"] += 1
            continue
        mine = _position_before(result.trace[ME], event["t"])
        theirs = _position_before(result.trace[event["other"]], event["t"])
        arcs = track.project(np.array([mine, theirs])).arc_length
        kinds["rear" if track.arc_delta(arcs[0], arcs[1]) > SIDE_BY_SIDE_M else "side"] += 1
    return kinds


def row(results: list[RaceResult], solo: float | None, laps: int, track: Track) -> list[str]:
    """The table cells of one heat, from the model's side."""
    mine = [r.car(ME) for r in results]
    behind = [c for c in mine if (c.grid_offset or 0.0) < 0]
    ahead = [c for c in mine if (c.grid_offset or 0.0) == 0]

    def wins(cars: list) -> str:
        won = sum(1 for c in cars if c.finish_position == 1 and c.status == "finished")
        return f"{won}/{len(cars)}"

    lost = [c.total_time / laps - solo for c in behind if c.total_time is not None and solo]
    unfinished = len(behind) - len(lost)
    kinds = sum((contact_kinds(r, track) for r in results), Counter())
    lost_cell = "-" if not lost else f"{mean(lost):+.2f}"
    if unfinished:
        lost_cell += f" ({unfinished} DNF)"
    return [
        wins(behind),
        wins(ahead),
        f"{sum(1 for c in behind if c.overtakes > 0)}/{len(behind)}",
        f"{mean(c.overtakes for c in mine):.2f}",
        f"{mean(c.at_fault_collisions for c in mine):.2f}",
        " / ".join(str(kinds[k]) for k in CONTACT_KINDS),
        lost_cell,
    ]


def target_note(slower: list[RaceResult]) -> str:
    """The head-to-head target's figures over ``slower``, the races against paced drivers
    below the model's pace: passed from behind, at-fault collisions a race."""
    mine = [r.car(ME) for r in slower]
    behind = [c for c in mine if (c.grid_offset or 0.0) < 0]
    passed = sum(1 for c in behind if c.overtakes > 0)
    faults = mean(c.at_fault_collisions for c in mine) if mine else 0.0
    share = f" ({passed / len(behind):.0%})" if behind else ""
    return (
        f"behind the paced drivers at {min(SLOWER):.0%}-{max(SLOWER):.0%}, every track: "
        f"passed in {passed} of {len(behind)} races{share}, at-fault {faults:.2f} a race "
        "(target: 90%, at most 0.1)"
    )


def main() -> None:
    """Parse options, race the gauntlet, write the table."""
    model: Any
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=SAMPLES / "sample-self-play.zip")
    parser.add_argument(
        "--teacher", action="store_true", help="run the scripted teacher through it, not --model"
    )
    parser.add_argument(
        "--field", type=Path, nargs="*", help="other model files (default: the other samples)"
    )
    parser.add_argument("--tracks", default=",".join(real_width_tracks()))
    parser.add_argument("--races", type=int, default=20, help="seeded races per rival")
    parser.add_argument("--laps", type=int, default=3)
    add_record_option(parser)
    args = parser.parse_args()
    field = args.field
    if field is None:
        field = [p for p in sorted(SAMPLES.glob("*.zip")) if p.resolve() != args.model.resolve()]
    if args.teacher:
        car = SCRIPTED_ME
    else:
        model = load_policy(args.model, non_finite="raise", name=f"car {ME}")
        car = model_car(ME, model.info.model_dump(mode="json"))
    subject = "the teacher" if args.teacher else args.model.name
    others = model_heats(field)
    columns = ["track", "rival", "wins from behind", "wins from ahead", "passed from behind",
               "overtakes/race", "at-fault/race", "at-fault: start / rear / side",
               "s/lap lost behind"]  # fmt: skip
    table = ResultTable(
        f"Gauntlet of {subject}: {args.races} races per rival, {args.laps} laps",
        columns,
        "ll" + "r" * 7,
    )
    slower: list[RaceResult] = []
    slower_names = {paced_name(p) for p in SLOWER}
    with Progress() as progress:
        for track in args.tracks.split(","):
            resolve_track(RaceConfig.build(track=track, cars=[car]))  # unknown names fail here
            road = get_track(track)
            if args.teacher:
                model = PassingPursuitPolicy(road, car.action_space)
            solo, heats = field_on(track, model, car, args.laps, others, table.notes)
            task = progress.add_task(track, total=len(heats) * args.races)
            for heat in heats:
                results = []
                for k in range(args.races):
                    results.append(race_heat(model, car, heat, track, args.laps, k))
                    progress.advance(task)
                table.add_row(track, heat.name, *row(results, solo, args.laps, road))
                if heat.name in slower_names:
                    slower += results
    table.notes.append(target_note(slower))
    write(table, args.record)


if __name__ == "__main__":
    main()
