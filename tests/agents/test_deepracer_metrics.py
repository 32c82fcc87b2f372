"""DeepRacer's ``EvaluationMetrics`` file of an evaluation race: one entry per lap, with the
simapp's meaning per field (read next to the evaluation simtrace written with it)."""

from __future__ import annotations

import csv
import json

import arena
from agents.evaluate import write_evaluation
from arena.race import RaceResult
from arena.simtrace import StepFacts

# Each incident holds the car for a penalty pause before it drives on.
PAUSE = ["pause"] * 3
LAP_ONE = ["in_progress"] * 8 + ["crashed", *PAUSE] + ["in_progress"] * 4
LAP_ONE += ["immobilized", *PAUSE, "in_progress", "immobilized", *PAUSE, "lap_complete"]
LAP_TWO = ["in_progress"] * 5 + ["crashed", *PAUSE, "in_progress", "crashed", *PAUSE]
LAP_TWO += ["in_progress"] * 3 + ["lap_complete"]
LAP_THREE = ["in_progress"] * 4 + ["off_track", *PAUSE, "in_progress", "time_up"]


def _race(statuses: list[str]) -> RaceResult:
    """A finished race of car0 whose steps have ``statuses``, as :func:`arena.race.run_race`
    records them (race time, progress and crashes so far)."""
    config = arena.make_config(laps=3, sensors=("lidar",))
    dt = config.control_dt
    facts, crashes, progress = [], 0, 0.0
    for step, status in enumerate(statuses, start=1):
        crashes += status == "crashed"
        progress = 0.0 if status == "lap_complete" else progress + 2.0 * (status == "in_progress")
        facts.append(
            StepFacts(
                t=step * dt,
                x=0.0,
                y=0.0,
                yaw=0.0,
                speed=1.0,
                steer=0.0,
                throttle=1.0,
                action=0,
                reward=1.0,
                progress=progress,
                status=status,
                all_wheels_on_track=status != "off_track",
                closest_waypoint=step,
                steps=step,
                done=status == "time_up",
                pause_left=0.0,
                crash_count=crashes,
                track_len=17.0,
            )
        )
    return RaceResult(
        config=config,
        cars=[],
        finish_order=[],
        duration=len(statuses) * dt,
        steps=len(statuses),
        trace={},
        facts={"car0": facts},
    )


def test_each_lap_counts_its_own_incidents_and_starts_where_the_lap_before_ended(tmp_path):
    folder = write_evaluation(tmp_path, _race(LAP_ONE + LAP_TWO + LAP_THREE))
    (metrics_file,) = (tmp_path / "metrics").glob("EvaluationMetrics-*.json")
    laps = json.loads(metrics_file.read_text())["metrics"]
    with (folder / "evaluation-simtrace" / "0-iteration.csv").open(newline="") as handle:
        trace = list(csv.DictReader(handle))

    counted = ("crash_count", "immobilized_count", "off_track_count", "reset_count")
    # (crashes, immobilised, off track, resets) per lap, as LAP_ONE, LAP_TWO and LAP_THREE hold
    assert [tuple(lap[k] for k in counted) for lap in laps] == [
        (1, 2, 0, 3),
        (2, 0, 0, 2),
        (0, 0, 1, 1),
    ]
    assert [lap["episode_status"] for lap in laps] == ["Lap complete", "Lap complete", "Time up"]

    ended = 0
    for episode, lap in enumerate(laps):
        rows = [row for row in trace if int(row["episode"]) == episode]
        assert lap["start_time"] == ended  # the race clock when the lap began, in ms
        ended = round(float(rows[-1]["tstamp"]) * 1000)
        assert lap["metric_time"] == ended
        assert lap["elapsed_time_in_milliseconds"] == ended - lap["start_time"]
    assert 0 < laps[1]["start_time"] < laps[2]["start_time"]
