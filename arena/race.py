"""``run_race``: drive policies through a race and collect a ``RaceResult``.

One runner serves the CLI, training evaluations and the league: anything with
``reset()`` and ``act(observation)`` (the :class:`arena.policy.Policy` protocol) can
drive. A policy with ``needs_params = True`` also receives the DeepRacer params
(built-in drivers use them; submitted models never do).
"""

from __future__ import annotations

import json
import math
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from gymnasium import spaces

from arena.config import RaceConfig
from arena.env import RacingEnv, RewardFunction
from arena.policy import Policy, policy_action
from arena.racing_metrics import CarStep, RacingMetrics
from arena.simtrace import StepFacts, step_facts

TRACE_COLUMNS = (
    "t",
    "x",
    "y",
    "yaw",
    "speed",
    "steer",
    "throttle",
    "action",
    "reward",
    "progress",
    "status",
    "all_wheels_on_track",
    "closest_waypoint",
)


@dataclass(frozen=True)
class CarResult:
    """One car's race: laps and times (simulated seconds, penalties included), incidents and
    racing metrics (:mod:`arena.racing_metrics`).

    ``gap_to_winner`` is the car's total time minus the winner's, in seconds: 0.0 for the
    winner, ``None`` for a car that did not finish (and for every car when none finished).
    ``grid_offset`` is where the car started, metres along the track from the front of the
    grid (0.0 for the front slot, negative behind it); ``None`` in results stored before it
    was recorded. ``dnf_reason`` says why a car the race's :class:`StepGuard` took out did
    not finish (its policy raised a fault, or its steps were over the time budget); ``None``
    for every other car.
    """

    name: str
    status: str
    laps: int
    lap_times: list[float]
    best_lap: float | None
    average_lap: float | None
    total_time: float | None
    off_track_count: int
    crash_count: int
    reset_count: int
    penalty_seconds: float
    distance: float
    finish_position: int
    overtakes: int = 0
    times_overtaken: int = 0
    at_fault_collisions: int = 0
    laps_led: int = 0
    gap_to_winner: float | None = None
    grid_offset: float | None = None
    dnf_reason: str | None = None


@dataclass(frozen=True)
class StepGuard:
    """When a car is taken out of a race for how its policy behaves; the other cars race on.

    ``faults`` are exception types a policy's ``act`` may raise that retire that car (DNF,
    the exception's text as its reason) instead of ending the race. ``budget_ms`` is the CPU
    time one ``act`` may take, on the calling thread's clock (as
    :mod:`submissions.onnx_checks` times a step at validation); a car whose fastest step of
    its last ``window`` steps is over it is retired too. ``None``: no budget. A retired car
    drives one more control step (its last action) and is then parked off the track.
    ``cars`` names the cars guarded (``None``: all of them); the others drive unwatched.
    """

    faults: tuple[type[Exception], ...] = ()
    budget_ms: float | None = None
    window: int = 10
    cars: frozenset[str] | None = None


@dataclass(frozen=True)
class RaceResult:
    """A finished race: the config it ran under, per-car results and a compact trace.

    ``trace`` maps car name to columns (:data:`TRACE_COLUMNS`, each a field of
    :class:`arena.simtrace.StepFacts`), one value per control step the car was racing;
    ``bots`` holds the bot cars' ``[x, y, yaw]`` per step and ``obstacles`` the boxes as
    ``[x, y, yaw, length, width]``. ``events`` lists the race's overtakes and contacts as
    :meth:`arena.racing_metrics.RaceEvent.to_dict` dicts, in time order. ``facts`` keeps
    each car's whole :class:`~arena.simtrace.StepFacts` per step for simtrace files; it
    lives only in the process that ran the race (``to_dict`` leaves it out, ``from_dict``
    has none).
    """

    config: RaceConfig
    cars: list[CarResult]
    finish_order: list[str]
    duration: float
    steps: int
    trace: dict[str, dict[str, list]] = field(repr=False)
    bots: list[list[list[float]]] = field(default_factory=list, repr=False)
    obstacles: list[list[float]] = field(default_factory=list, repr=False)
    events: list[dict[str, Any]] = field(default_factory=list, repr=False)
    facts: dict[str, list[StepFacts]] = field(default_factory=dict, repr=False, compare=False)

    def car(self, name: str) -> CarResult:
        """The result of the car called ``name``."""
        for result in self.cars:
            if result.name == name:
                return result
        raise KeyError(name)

    def replay_data(self) -> dict[str, Any]:
        """What a replay draws: ``trace``, ``bots``, ``obstacles`` and ``events``."""
        return {
            "trace": self.trace,
            "bots": self.bots,
            "obstacles": self.obstacles,
            "events": self.events,
        }

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (floats at full precision)."""
        return {
            "config": json.loads(self.config.to_json()),
            "ruleset_hash": self.config.ruleset_hash(),
            "cars": [asdict(c) for c in self.cars],
            "finish_order": self.finish_order,
            "duration": self.duration,
            "steps": self.steps,
            **self.replay_data(),
        }

    def to_json(self) -> str:
        """Canonical JSON of :meth:`to_dict`; equal results give equal text."""
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RaceResult:
        """Rebuild a result stored with :meth:`to_dict` (results stored before racing
        metrics existed come back with zero counts, no gaps and no events)."""
        return cls(
            config=RaceConfig.model_validate(data["config"]),
            cars=[CarResult(**c) for c in data["cars"]],
            finish_order=list(data["finish_order"]),
            duration=data["duration"],
            steps=data["steps"],
            trace=data["trace"],
            bots=data.get("bots", []),
            obstacles=data.get("obstacles", []),
            events=data.get("events", []),
        )


def _idle(space: spaces.Space) -> Any:
    """An action of ``space`` for a car that has none of its own (retired on its first step)."""
    return 0 if isinstance(space, spaces.Discrete) else np.zeros(space.shape, np.float32)


class _Steward:
    """Applies a :class:`StepGuard` to the cars' policies: times each step, retires cars."""

    def __init__(self, env: RacingEnv, guard: StepGuard) -> None:
        self.env = env
        self.guard = guard
        self.reasons: dict[str, str] = {}
        self._last: dict[str, Any] = {}
        self._times: dict[str, deque[float]] = {}

    def act(self, name: str, policy: Policy, observation: dict, info: dict) -> Any:
        """The car's action this step; a retired car repeats its last one."""
        if name in self.reasons:
            return self._last.get(name, _idle(self.env.action_space(name)))
        if self.guard.cars is not None and name not in self.guard.cars:
            return policy_action(policy, observation, info)
        start = time.thread_time()
        try:
            action = policy_action(policy, observation, info)
        except self.guard.faults as exc:
            self._retire(name, f"model fault: {exc}")
            return self._last.get(name, _idle(self.env.action_space(name)))
        self._last[name] = action
        budget = self.guard.budget_ms
        if budget is not None:
            took = self._times.setdefault(name, deque(maxlen=self.guard.window))
            took.append((time.thread_time() - start) * 1000.0)
            if len(took) == took.maxlen and min(took) > budget:
                self._retire(
                    name,
                    f"too slow: its fastest of {len(took)} steps took {min(took):.1f} ms of "
                    f"CPU time, over the budget of {budget:g} ms a step",
                )
        return action

    def _retire(self, name: str, reason: str) -> None:
        self.reasons[name] = reason[:500]
        self.env.retire(name)


def run_race(
    config: RaceConfig,
    policies: Mapping[str, Policy],
    *,
    reward_functions: RewardFunction | Mapping[str, RewardFunction] | None = None,
    on_step: Callable[[RacingEnv], None] | None = None,
    record_trace: bool = True,
    guard: StepGuard | None = None,
) -> RaceResult:
    """Race ``policies`` (one per car name in ``config.cars``) until every car is done.

    ``on_step(env)`` is called after each control step (progress bars, video frames).
    ``guard`` retires cars whose policy faults or is too slow (:class:`StepGuard`);
    without one a policy's exception ends the race. The same config, seed and policies give
    an identical result (a step budget depends on the machine's speed too).
    """
    names = [c.name for c in config.cars]
    missing = [n for n in names if n not in policies]
    if missing:
        raise ValueError(f"no policy for car(s) {missing}")
    env = RacingEnv(config, reward_functions=reward_functions)
    try:
        observations, infos = env.reset(seed=config.seed)
        for name in names:
            policies[name].reset()
        trace: dict[str, dict[str, list]] = {n: {c: [] for c in TRACE_COLUMNS} for n in names}
        facts: dict[str, list[StepFacts]] = {n: [] for n in names}
        bots: list[list[list[float]]] = []
        obstacles = [list(o) for o in env.obstacle_poses()]
        last_info = dict(infos)
        grid = _grid_offsets(env, names)
        metrics = RacingMetrics(grid)
        steward = _Steward(env, guard or StepGuard())
        steps = 0
        while env.agents:
            actions = {
                a: steward.act(a, policies[a], observations[a], last_info[a]) for a in env.agents
            }
            observations, rewards, _, _, infos = env.step(actions)
            steps += 1
            last_info.update(infos)
            metrics.update(env.time, {a: CarStep.from_info(info) for a, info in infos.items()})
            if record_trace:
                _record(env, trace, facts, actions, rewards, infos)
                if env.bot_poses():
                    bots.append([list(b) for b in env.bot_poses()])
            if on_step is not None:
                on_step(env)
        result = _result(config, env, steps, trace, facts, bots, obstacles, metrics, grid)
        return _with_reasons(result, steward.reasons)
    finally:
        env.close()


def _with_reasons(result: RaceResult, reasons: Mapping[str, str]) -> RaceResult:
    """``result`` with each retired car's DNF reason."""
    if not reasons:
        return result
    cars = [replace(c, dnf_reason=reasons[c.name]) if c.name in reasons else c for c in result.cars]
    return replace(result, cars=cars)


def _grid_offsets(env: RacingEnv, names: list[str]) -> dict[str, float]:
    """Each car's start, metres along the track from the front of the grid (<= 0)."""
    first = env.record(names[0]).start_arc
    ahead = {n: float(env.track.arc_delta(first, env.record(n).start_arc)) for n in names}
    front = max(ahead.values())
    return {n: ahead[n] - front for n in names}


def _record(
    env: RacingEnv,
    trace: dict[str, dict[str, list]],
    facts: dict[str, list[StepFacts]],
    actions: Mapping[str, Any],
    rewards: Mapping[str, float],
    infos: Mapping[str, dict[str, Any]],
) -> None:
    """Append each stepped car's facts, and the trace columns taken from them."""
    poses = env.car_poses()
    for agent, info in infos.items():
        step = step_facts(info, poses[agent], actions[agent], rewards[agent])
        facts[agent].append(step)
        for column, values in trace[agent].items():
            values.append(getattr(step, column))


def _result(
    config: RaceConfig,
    env: RacingEnv,
    steps: int,
    trace: dict[str, dict[str, list]],
    facts: dict[str, list[StepFacts]],
    bots: list[list[list[float]]],
    obstacles: list[list[float]],
    metrics: RacingMetrics,
    grid: Mapping[str, float],
) -> RaceResult:
    rows = []
    for car in config.cars:
        rec = env.record(car.name)
        laps = list(rec.lap_times)
        finished = rec.finished
        status = "finished" if finished else ("time_up" if rec.truncated else "dnf")
        rows.append(
            {
                "name": car.name,
                "status": status,
                "laps": len(laps),
                "lap_times": laps,
                "best_lap": min(laps) if laps else None,
                "average_lap": sum(laps) / len(laps) if laps else None,
                "total_time": sum(laps) if finished else None,
                "off_track_count": rec.off_track_count,
                "crash_count": rec.crash_count,
                "reset_count": rec.reset_count,
                "penalty_seconds": rec.penalty_seconds,
                "distance": rec.distance,
                **asdict(metrics.cars[car.name]),
                "grid_offset": grid[car.name],
            }
        )
    order = sorted(
        rows,
        key=lambda r: (
            r["status"] != "finished",
            r["total_time"] if r["total_time"] is not None else math.inf,
            -r["laps"],
            -r["distance"],
            r["name"],
        ),
    )
    position = {r["name"]: i + 1 for i, r in enumerate(order)}
    winner_time = order[0]["total_time"]
    cars = [
        CarResult(
            **r,
            finish_position=position[r["name"]],
            gap_to_winner=None if r["total_time"] is None else r["total_time"] - winner_time,
        )
        for r in rows
    ]
    return RaceResult(
        config=config,
        cars=cars,
        finish_order=[r["name"] for r in order],
        duration=env.time,
        steps=steps,
        trace=trace,
        bots=bots,
        obstacles=obstacles,
        events=[e.to_dict() for e in metrics.events],
        facts=facts,
    )
