"""One car's step as facts, and DeepRacer's simtrace CSV (read by deepracer-utils) made of them.

:func:`step_facts` is the one place that reads what :meth:`arena.env.RacingEnv.step` gave a
car (its info and params) together with its pose, action and reward. The race trace of
:class:`arena.race.RaceResult` keeps some of these facts as columns; :func:`simtrace_row`
turns them into a simtrace row for training rollouts (:mod:`agents.vecenv`) and evaluation
races (:func:`race_rows`, :func:`lap_rows`) alike, so both files agree column by column on the
same steps.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from arena.race import RaceResult

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


@dataclass(frozen=True, slots=True)
class StepFacts:
    """What one control step of one car produced.

    ``x``, ``y``, ``yaw`` (radians) and ``speed`` are the car origin's measured pose;
    ``steer`` (degrees) and ``throttle`` (m/s) the commanded action, ``action`` its index
    (discrete) or its two values (continuous). ``steps`` counts this episode's steps (1 on
    the first); ``done`` is true on the step that ends the car's episode (a race: its
    last step). ``pause_left`` is the penalty time still to serve, counting down from the
    full penalty on the incident's step to 0 once the car runs again; ``crash_count`` the
    crashes so far this episode.
    """

    t: float
    x: float
    y: float
    yaw: float
    speed: float
    steer: float
    throttle: float
    action: int | list[float]
    reward: float
    progress: float
    status: str
    all_wheels_on_track: bool
    closest_waypoint: int
    steps: int
    done: bool
    pause_left: float
    crash_count: int
    track_len: float


def action_value(action: Any) -> int | list[float]:
    """An action as plain JSON data: an ``int`` index or a list of floats."""
    arr = np.asarray(action)
    if arr.ndim == 0:
        return int(arr)
    return [float(v) for v in arr.reshape(-1)]


def step_facts(
    info: Mapping[str, Any],
    pose: tuple[float, float, float, float],
    action: Any,
    reward: float,
) -> StepFacts:
    """The facts of one car's step: its ``info`` from ``step``, ``(x, y, yaw, speed)``,
    the action it was given and its reward."""
    params = info["params"]
    x, y, yaw, speed = pose
    return StepFacts(
        t=info["time"],
        x=x,
        y=y,
        yaw=yaw,
        speed=speed,
        steer=params["steering_angle"],
        throttle=params["speed"],
        action=action_value(action),
        reward=reward,
        progress=info["progress"],
        status=info["episode_status"],
        all_wheels_on_track=params["all_wheels_on_track"],
        closest_waypoint=params["closest_waypoints"][1],
        steps=params["steps"],
        done=info["done"],
        pause_left=info["pause_left"],
        crash_count=info["crash_count"],
        track_len=params["track_length"],
    )


def simtrace_row(facts: StepFacts, episode: int, wall_clock: float) -> dict[str, Any]:
    """One simtrace row (keys :data:`SIMTRACE_COLUMNS`) with DeepRacer's meaning per column.

    Where Slipstream's writers once differed, DeepRacer's simapp decides:

    - ``done``: the car's episode ended on this step (a lap or the race finished, an
      incident in training, the last allowed reset used, time up); a race's penalty pause
      is not an end.
    - ``pause_duration``: penalty seconds still to serve: the full penalty on the
      incident's step, counting down while the car is held, 0 while it runs (always 0
      in training, where incidents end the episode instead).
    - ``obstacle_crash_counter``: crashes so far in the episode (cumulative, from 0 at its
      start), not a per-step flag.
    - ``progress``: 100 on a ``lap_complete`` step (the arena's progress has already
      wrapped into the next lap there), so a completed lap reads as complete.

    ``yaw`` is in degrees; ``action`` is the index for discrete spaces and
    ``"[steer, speed]"`` (4 decimals) for continuous ones; ``tstamp`` is simulated time.
    """
    action = facts.action
    if isinstance(action, list):
        action = "[" + ", ".join(f"{v:.4f}" for v in action) + "]"
    return {
        "episode": episode,
        "steps": facts.steps,
        "X": facts.x,
        "Y": facts.y,
        "yaw": math.degrees(facts.yaw),
        "steer": facts.steer,
        "throttle": facts.throttle,
        "action": action,
        "reward": facts.reward,
        "done": facts.done,
        "all_wheels_on_track": facts.all_wheels_on_track,
        "progress": 100.0 if facts.status == "lap_complete" else facts.progress,
        "closest_waypoint": facts.closest_waypoint,
        "track_len": facts.track_len,
        "tstamp": facts.t,
        "episode_status": facts.status,
        "pause_duration": facts.pause_left,
        "obstacle_crash_counter": facts.crash_count,
        "wall_clock": wall_clock,
    }


def race_rows(
    result: RaceResult, car: str, episode: int = 0, wall_clock: float = 0.0
) -> list[dict[str, Any]]:
    """Simtrace rows of one car of an :class:`arena.race.RaceResult` run in this process.

    Step facts are not stored with a result, so one rebuilt with ``from_dict`` has none:
    that is a ``ValueError``.
    """
    if car not in result.facts:
        raise ValueError(f"no step facts for car {car!r}: simtrace needs a race run here")
    return [simtrace_row(facts, episode, wall_clock) for facts in result.facts[car]]


def lap_rows(result: RaceResult, car: str, wall_clock: float = 0.0) -> list[dict[str, Any]]:
    """Simtrace rows of one car's race with one episode per lap, as DeepRacer's evaluation.

    Lap ``k`` (from 0) is episode ``k``: its steps restart at 1, its crash counter at 0, and
    its last row (``lap_complete``) has ``done`` true and progress 100. An unfinished last
    lap is an episode of its own, ending with the race's last row. ``ValueError`` as
    :func:`race_rows` for a result without step facts.
    """
    if car not in result.facts:
        raise ValueError(f"no step facts for car {car!r}: simtrace needs a race run here")
    rows: list[dict[str, Any]] = []
    lap, steps, crashes_before = 0, 0, 0
    for facts in result.facts[car]:
        steps += 1
        lap_done = facts.status == "lap_complete"
        lap_facts = replace(
            facts,
            steps=steps,
            done=facts.done or lap_done,
            crash_count=facts.crash_count - crashes_before,
        )
        rows.append(simtrace_row(lap_facts, lap, wall_clock))
        if lap_done:
            lap, steps, crashes_before = lap + 1, 0, facts.crash_count
    return rows


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
