"""Behind slower cars with the teacher riding along: does the model do what it would?

The model races the gauntlet's paced pursuit racers (``h2h_gauntlet.py``: 60, 80 and 90%
of its solo pace) from behind, seeds 0, 2, 4, ... (the grid as the gauntlet's races
started behind). At every step a shadow teacher (``arena.pursuit.PassingPursuitPolicy``,
the passing pursuit driver that imitation copies) reads the model car's params and says
what it would command there; the model's own action drives the car. Counted from the
start's 2 s on (the teacher follows every car before that), over the steps with the rival
ahead within the teacher's planning horizon:

- how often the teacher would be passing from the states the model reaches;
- how far the model's steering is from the teacher's (in units of the largest steering
  angle, so 0-2) when the teacher would pass and when it would follow;
- how much faster than the teacher's command the model drives (m/s) in each;
- how often a race the teacher would begin a pass (a model that hesitates makes it begin,
  give up and begin again), and in how many of the steps it would be passing the model
  car is out on the teacher's side of the rival;

and per race the model's overtakes and at-fault contacts. A model that follows where the
teacher would pass, or drives faster than it where it would follow (into the rival), shows
here what its gauntlet row does not say.

    .venv/bin/python benchmarks/teacher_agreement.py --model league/demo_models/sample-self-play.zip

``--teacher`` drives the teacher itself in the model's place: its own rows to compare with.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
from h2h_gauntlet import ME, PACES, SAMPLES, SCRIPTED_ME, field_on, paced_name, race_heat
from harness import ResultTable, add_record_option, write

from arena.actions import MAX_STEERING_DEG
from arena.pursuit import (
    PASS_HORIZON_M,
    PASS_HORIZON_S,
    START_FOLLOW_STEPS,
    PassingPursuitPolicy,
    car_offset,
    object_offset,
)
from league.jobs.evaluation import model_car
from submissions import load_policy
from tracks.catalog import get_track

SLOWER = tuple(paced_name(p) for p in PACES if p < 1.0)  # the heats of slower racers


class ShadowedModel:
    """The model's policy, with the teacher reading the same params each step; records
    ``(teacher passing, teacher command, model command, model car on the teacher's pass
    side)`` with the rival ahead in range (a command: steering degrees and speed, in
    either kind of action space), and counts the passes the teacher begins."""

    needs_params = True

    def __init__(self, model: Any, teacher: PassingPursuitPolicy) -> None:
        self.model, self.teacher = model, teacher
        self.rows: list[tuple[float, ...]] = []
        self.steps = 0
        self.passes_begun = 0

    def reset(self) -> None:
        """Start of a race, for both."""
        self.model.reset()
        self.teacher.reset()
        self.steps = 0

    def act(self, observation: dict[str, Any], params: dict[str, Any]) -> Any:
        """The model's action; the teacher's, from the same params, is recorded beside it."""
        scripted = getattr(self.model, "needs_params", False)  # --teacher
        action = self.model.act(observation, params) if scripted else self.model.act(observation)
        was_passing = self.teacher.is_passing
        shadow = self.teacher.act(observation, params)
        self.passes_begun += self.teacher.is_passing and not was_passing
        self.steps += 1
        if params["objects_distance"] and self.steps > START_FOLLOW_STEPS:
            ahead = params["objects_distance"][0]  # the one rival
            gap = float(self.teacher.track.arc_delta(params["projection_distance"], ahead))
            horizon = max(PASS_HORIZON_M, PASS_HORIZON_S * float(params["speed"]))
            if 0.0 < gap <= horizon:
                passing = float(self.teacher.is_passing)
                side = self.teacher.pass_side or 0.0
                on_side = float(side * (car_offset(params) - object_offset(params, 0)) > 0.0)
                space = self.teacher.space
                commands = (*space.to_command(shadow), *space.to_command(action))
                self.rows.append((passing, *commands, on_side))
        return action


def agreement(rows: list[tuple[float, ...]]) -> list[str]:
    """The table's cells of agreement for one heat's recorded steps."""
    d = np.array(rows).reshape(-1, 6)
    passing = d[:, 0] == 1.0
    steer = np.abs(d[:, 3] - d[:, 1]) / MAX_STEERING_DEG
    faster = d[:, 4] - d[:, 2]

    def mean(values: np.ndarray, where: np.ndarray, fmt: str) -> str:
        return format(values[where].mean(), fmt) if where.any() else "-"

    return [
        str(len(d)),
        f"{passing.mean():.0%}" if len(d) else "-",
        mean(steer, passing, ".2f"),
        mean(steer, ~passing, ".2f"),
        mean(faster, passing, "+.2f"),
        mean(faster, ~passing, "+.2f"),
        mean(d[:, 5] * 100.0, passing, ".0f") + ("%" if passing.any() else ""),
    ]


def main() -> None:
    """Parse options, race the model behind the slower racers, write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=SAMPLES / "sample-self-play.zip")
    parser.add_argument("--tracks", default="slipstream_speedway,grand_tour")
    parser.add_argument("--races", type=int, default=10, help="races started behind per rival")
    parser.add_argument("--laps", type=int, default=2)
    parser.add_argument("--teacher", action="store_true", help="the teacher drives instead")
    add_record_option(parser)
    args = parser.parse_args()
    if args.teacher:
        car = SCRIPTED_ME
    else:
        model = load_policy(args.model, non_finite="raise", name=f"car {ME}")
        car = model_car(ME, model.info.model_dump(mode="json"))
    columns = ["track", "rival", "steps behind", "teacher would pass",
               "steer off: passing", "steer off: following", "faster (m/s): passing",
               "faster (m/s): following", "on its side: passing", "passes begun/race",
               "passed from behind", "overtakes/race", "at-fault/race"]  # fmt: skip
    subject = "the teacher" if args.teacher else args.model.name
    table = ResultTable(
        f"{subject} behind slower racers, the teacher riding along: "
        f"{args.races} races per rival, {args.laps} laps",
        columns,
    )
    for track in args.tracks.split(","):
        if args.teacher:
            model = PassingPursuitPolicy(get_track(track), car.action_space)
        _, heats = field_on(track, model, car, args.laps, [], table.notes)
        teacher = PassingPursuitPolicy(get_track(track), car.action_space)
        for heat in [h for h in heats if h.name in SLOWER]:
            shadowed = ShadowedModel(model, teacher)
            races = [
                race_heat(shadowed, car, heat, track, args.laps, k)
                for k in range(0, 2 * args.races, 2)
            ]
            mine = [race.car(ME) for race in races]
            passed = sum(1 for r in mine if r.overtakes)
            table.add_row(
                track,
                heat.name,
                *agreement(shadowed.rows),
                f"{shadowed.passes_begun / len(races):.1f}",
                f"{passed}/{len(mine)}",
                f"{sum(r.overtakes for r in mine) / len(mine):.2f}",
                f"{sum(r.at_fault_collisions for r in mine) / len(mine):.2f}",
            )
    write(table, args.record)


if __name__ == "__main__":
    main()
