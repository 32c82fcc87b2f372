"""Pre-flight: one short race of a submission in the arena, before it is uploaded."""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel

from arena.config import RaceConfig
from arena.race import run_race
from submissions.policy import load_policy


class PreflightResult(BaseModel):
    """How the model did: did it finish, in what time, with what incidents."""

    track: str
    laps: int
    status: str
    laps_completed: int
    lap_times: list[float]
    best_lap: float | None
    off_track_count: int
    crash_count: int
    reset_count: int

    @property
    def finished(self) -> bool:
        """Completed every lap within the time limit."""
        return self.status == "finished"


def preflight(
    source: str | Path | bytes, track: str, laps: int = 1, time_limit_s: float = 90.0, seed: int = 0
) -> PreflightResult:
    """Validate and load ``source``, race it alone on ``track`` in race mode, report.

    Raises :class:`submissions.validator.InvalidSubmission` if the file is refused and
    :class:`arena.config.ConfigError` for an unknown track.
    """
    policy = load_policy(source)
    info = policy.info
    car = {
        "name": "model",
        "sensors": info.sensors,
        "action_space": info.action_space,
        "stack_size": info.stack_size,
    }
    if info.lidar_config is not None:
        car["lidar_config"] = info.lidar_config
    config = RaceConfig.build(
        track=track, cars=[car], laps=laps, time_limit_s=time_limit_s, seed=seed
    )
    result = run_race(config, {"model": policy}, record_trace=False).car("model")
    return PreflightResult(
        track=track,
        laps=laps,
        status=result.status,
        laps_completed=result.laps,
        lap_times=result.lap_times,
        best_lap=result.best_lap,
        off_track_count=result.off_track_count,
        crash_count=result.crash_count,
        reset_count=result.reset_count,
    )
