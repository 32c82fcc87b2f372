"""Evaluate a policy in race mode: results table, simtrace and replay files."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rich.table import Table

import arena
from agents.deepracer_metrics import TrainingMetricsLog, write_evaluation_metrics
from agents.networks import observation_groups
from agents.settings import TrainSettings
from arena.actions import ContinuousActionSpace, DiscreteActionSpace
from arena.config import RaceConfig, resolve_track
from arena.race import RaceResult, run_race
from arena.simtrace import lap_rows, write_simtrace


class TorchPolicy:
    """Drives a car with an rsl-rl actor's deterministic output (``arena.policy.Policy``)."""

    def __init__(self, actor: torch.nn.Module, discrete: bool) -> None:
        self.actor = actor
        self.discrete = discrete

    def reset(self) -> None:
        """Stateless: nothing to forget."""

    def act(self, observation: dict[str, Any]) -> Any:
        """Greedy action: an index (discrete) or two values in ``[-1, 1]``."""
        groups = observation_groups({k: np.asarray(v)[None] for k, v in observation.items()})
        with torch.inference_mode():
            out = self.actor(groups.to(next(self.actor.parameters()).device))[0].cpu()
        if self.discrete:
            return int(out.argmax())
        return out.clamp(-1.0, 1.0).numpy().astype(np.float32)


def evaluation_config(
    track: str,
    race_type: str,
    sensors: tuple[str, ...] | list[str],
    action_space: DiscreteActionSpace | ContinuousActionSpace,
    *,
    laps: int = 3,
    seed: int = 0,
    time_limit_s: float = 180.0,
    num_cars: int | None = None,
    direction: str | None = None,
    stack_size: int = 1,
    **rules: Any,
) -> RaceConfig:
    """A race-mode config for evaluating one trained policy (``direction``: the file's;
    ``rules``: other :class:`RaceConfig` fields, such as the race type's ``obstacles`` or
    ``bots``)."""
    return arena.make_config(
        track=track,
        direction=direction,
        race_type=race_type,
        num_cars=num_cars,
        sensors=tuple(sensors),
        action_space=action_space,
        mode="race",
        seed=seed,
        laps=laps,
        time_limit_s=time_limit_s,
        stack_size=stack_size,
        **rules,
    )


def model_opponent(path: str | Path, settings: TrainSettings) -> Any:
    """A trained model (``model.zip`` or ``.onnx``) that drives the other cars of a run's
    evaluation greedily; it must read the run's sensors and act in its kind of space."""
    from agents.selfplay import opponent_policy, read_policy_graph

    runner = opponent_policy(read_policy_graph(path), settings.discrete, name=Path(path).name)
    unknown = sorted(set(runner.input_names) - set(settings.sensors))
    if unknown:
        raise ValueError(
            f"{path} reads {', '.join(unknown)}, which this run's cars do not have "
            f"(sensors: {', '.join(settings.sensors)})"
        )
    return runner


def run_opponent(settings: TrainSettings) -> Any | None:
    """The opponent a run's evaluations race: a head-to-model run's first ``--opponent``
    (the parent it learns to beat), else None (the policy races itself)."""
    if settings.race_type != "head_to_model" or not settings.opponent:
        return None
    return model_opponent(settings.opponent[0], settings)


def evaluate_policy(
    config: RaceConfig,
    policy: Any,
    replay_path: Path | None = None,
    reward_function: Callable[[dict[str, Any]], float] | None = None,
    opponent: Any | None = None,
) -> RaceResult:
    """Race ``policy`` in the first car of ``config`` and ``opponent`` (default: ``policy``
    itself) in every other car; optionally write a replay GIF.

    ``reward_function`` only fills the trace's reward column (default: follow the centre).
    """
    from arena.replay import ReplayWriter

    writer = ReplayWriter(resolve_track(config)[0]) if replay_path is not None else None
    first = config.cars[0].name
    policies = {
        car.name: policy if car.name == first or opponent is None else opponent
        for car in config.cars
    }
    result = run_race(
        config,
        policies,
        reward_functions=reward_function,
        on_step=writer.add if writer else None,
    )
    if writer is not None and replay_path is not None:
        replay_path.parent.mkdir(parents=True, exist_ok=True)
        writer.save(replay_path)
    return result


def evaluation_dir(run_dir: Path) -> Path:
    """A new ``RUN/evaluation-<YYYYMMDDHHMMSS>`` folder (one second later if taken)."""
    stamp = datetime.now()
    while True:
        path = Path(run_dir) / f"evaluation-{stamp:%Y%m%d%H%M%S}"
        if not path.exists():
            path.mkdir(parents=True)
            return path
        stamp = datetime.fromtimestamp(stamp.timestamp() + 1)


def write_evaluation(
    run_dir: Path,
    result: RaceResult,
    folder: Path | None = None,
    training_log: TrainingMetricsLog | None = None,
) -> Path:
    """Write the evaluation simtrace (first car; one episode per lap, as DeepRacer) in
    deepracer-for-cloud's layout, and its laps to an ``EvaluationMetrics`` file, or for a
    periodic evaluation during training to ``training_log`` (as deepracer-for-cloud does)."""
    folder = folder or evaluation_dir(run_dir)
    rows = lap_rows(result, result.config.cars[0].name, wall_clock=time.time())
    write_simtrace(folder / "evaluation-simtrace" / "0-iteration.csv", rows)
    if training_log is None:
        write_evaluation_metrics(run_dir, rows)
    else:
        training_log.add_evaluation(rows)
    return folder


@dataclass(frozen=True)
class EvalSummary:
    """Headline numbers of an evaluation race's first car."""

    laps: int
    progress: float  # % of the race's laps, the unfinished one in part
    best_lap: float | None
    total_time: float | None  # None unless the car finished
    off_track: int
    crashes: int
    resets: int
    status: str
    also: tuple[EvalSummary, ...] = ()  # the same evaluation's races on further tracks

    @property
    def races(self) -> tuple[EvalSummary, ...]:
        """The evaluation's races: this one, then those on further tracks."""
        return (self, *self.also)

    @property
    def pace_lap(self) -> float | None:
        """The car's pace as a lap time: its mean lap if it finished, else its best lap
        (None if it finished no lap)."""
        if self.total_time is not None and self.laps:
            return self.total_time / self.laps
        return self.best_lap

    @property
    def score(self) -> tuple[float, float, float]:
        """Order of merit over the evaluation's races, higher is better: mean progress,
        then fewer off-tracks and crashes, then an earlier finish (both summed)."""
        races = self.races
        progress = sum(r.progress for r in races) / len(races)
        incidents = sum(r.off_track + r.crashes for r in races)
        finish = sum(math.inf if r.total_time is None else r.total_time for r in races)
        return (progress, -float(incidents), -finish)

    def clean(self, laps: int) -> bool:
        """Whether every race of the evaluation ran ``laps`` laps without leaving the track."""
        return all(r.laps >= laps and r.off_track == 0 for r in self.races)


def summary(result: RaceResult) -> EvalSummary:
    """Headline numbers of the first car: laps, progress, best lap, incidents."""
    car = result.car(result.config.cars[0].name)
    progress = result.trace.get(car.name, {}).get("progress") or [0.0]
    partial = 0.0 if car.status == "finished" else float(progress[-1]) / 100.0
    return EvalSummary(
        laps=car.laps,
        progress=min(100.0, 100.0 * (car.laps + partial) / result.config.laps),
        best_lap=car.best_lap,
        total_time=car.total_time,
        off_track=car.off_track_count,
        crashes=car.crash_count,
        resets=car.reset_count,
        status=car.status,
    )


def evaluation_summary(races: list[RaceResult]) -> EvalSummary:
    """The headline numbers of an evaluation's first race, with its further races'
    (:attr:`EvalSummary.also`)."""
    first, *others = races
    return replace(summary(first), also=tuple(summary(race) for race in others))


def results_table(result: RaceResult) -> Table:
    """A Rich table: per car, laps and lap times, off-tracks, crashes, resets."""
    table = Table(title=f"{result.config.track} - {result.config.race_type}")
    for column in ("car", "status", "laps", "lap times (s)", "best", "total", "off", "crash"):
        table.add_column(column)
    table.add_column("resets")
    for car in result.cars:
        table.add_row(
            car.name,
            car.status,
            str(car.laps),
            ", ".join(f"{t:.2f}" for t in car.lap_times) or "-",
            f"{car.best_lap:.2f}" if car.best_lap is not None else "-",
            f"{car.total_time:.2f}" if car.total_time is not None else "-",
            str(car.off_track_count),
            str(car.crash_count),
            str(car.reset_count),
        )
    return table
