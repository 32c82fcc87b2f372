"""Re-score a logged run with a reward function: the confined child of ``POST /api/rescore``.

``python -m agents.rescore WORKDIR`` runs inside the league's sandbox. ``WORKDIR`` holds
``steps.json`` (what :func:`league.training.rescore.steps_document` wrote: the track, its
direction, the race type, the car and one column per logged field, one value per control
step), ``reward.py`` (the racer's edited reward function) and, when the model's own reward
function is known, ``original.py`` (whose errors only leave ``original`` null). For every
step the child rebuilds the DeepRacer ``params`` dict with the arena's own builder
(:func:`arena.params.build_params`) and calls each reward function on it. It prints one
JSON line: ``{"reward": [...], "original": [...] | null}``, or ``{"error": message}``
naming the file, the step and the line.

Rebuilt exactly from the log: ``x``, ``y``, ``heading``, ``speed`` and ``steering_angle``
(the commanded action), ``progress``, ``all_wheels_on_track``, ``is_offtrack``,
``is_crashed``, ``sim_time`` and everything the track decides (``waypoints``,
``closest_waypoints``, ``distance_from_center``, ``is_left_of_center``, ``track_width``,
``track_length``, ``projection_distance``, ``is_reversed``). Approximated: ``steps``
counts the logged steps from 1 (a race restarts nothing), and the object keys carry
DeepRacer's no-object defaults (other cars, bots and boxes are not in the per-car log).
"""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from agents.train_job import REWARD_FILE

STEPS_FILE = "steps.json"
ORIGINAL_FILE = "original.py"
MAX_ERROR_CHARS = 800


def _emit(record: dict[str, Any]) -> None:
    print(json.dumps(record, separators=(",", ":")), flush=True)


def all_params(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """The params dict of every logged step of ``doc`` (the ``steps.json`` document)."""
    from arena.car_spec import DEFAULT_CAR
    from arena.config import RaceConfig, resolve_track
    from arena.params import ObjectsView, build_params

    track, is_reversed = resolve_track(
        RaceConfig(track=doc["track"], direction=doc.get("direction"))
    )
    cols = doc["columns"]
    yaw = np.asarray(cols["yaw"], dtype=float)
    ahead = DEFAULT_CAR.model_point_ahead  # the log holds the car origin (rear axle)
    points = np.column_stack(
        [
            np.asarray(cols["x"], dtype=float) + ahead * np.cos(yaw),
            np.asarray(cols["y"], dtype=float) + ahead * np.sin(yaw),
        ]
    ).reshape(-1, 2)
    if not len(points):
        return []
    projection = track.project(points)
    waypoints = [tuple(map(float, w)) for w in track.waypoints]
    empty = ObjectsView.empty()
    return [
        build_params(
            track=track,
            is_reversed=is_reversed,
            model_point=points[i],
            yaw=float(yaw[i]),
            projection=projection,
            index=i,
            progress=float(cols["progress"][i]),
            steps=int(cols["steps"][i]),
            speed=float(cols["throttle"][i]),
            steering_angle=float(cols["steer"][i]),
            all_wheels_on_track=bool(cols["all_wheels_on_track"][i]),
            is_offtrack=cols["status"][i] == "off_track",
            is_crashed=cols["status"][i] == "crashed",
            objects=empty,
            waypoints=waypoints,
            sim_time=float(cols["t"][i]),
        )
        for i in range(len(points))
    ]


def score(path: Path, race_type: str, car: str, params: list[dict[str, Any]]) -> list[float]:
    """``reward_function`` of the file at ``path`` on each of ``params``, in order."""
    from agents.rewards import load_reward_function
    from arena.params import call_reward

    fn = load_reward_function(path, race_type)
    return [call_reward(fn, car, step + 1, p) for step, p in enumerate(params)]


def main(argv: list[str] | None = None) -> int:
    """Entry point of the confined child (see the module docstring)."""
    args = sys.argv[1:] if argv is None else argv
    workdir = Path(args[0])
    doc = json.loads((workdir / STEPS_FILE).read_text())
    try:
        params = all_params(doc)
        reward = score(workdir / REWARD_FILE, doc["race_type"], doc["car"], params)
    except (ValueError, RuntimeError) as exc:  # RewardFunctionError, RewardRaised, bad value
        message = str(exc).replace(f"{workdir}/", "")
        _emit({"error": message[:MAX_ERROR_CHARS]})
        return 0
    answer: dict[str, Any] = {"reward": reward, "original": None}
    if (workdir / ORIGINAL_FILE).is_file():
        # the model's own function: when it cannot score the log, there is no original
        with contextlib.suppress(ValueError, RuntimeError):
            answer["original"] = score(
                workdir / ORIGINAL_FILE, doc["race_type"], doc["car"], params
            )
    _emit(answer)
    return 0


if __name__ == "__main__":
    sys.exit(main())
