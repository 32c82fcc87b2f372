"""The re-score child rebuilds, from a logged run, the params the reward function saw."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Any

import pytest

from agents.evaluate import write_evaluation
from agents.rescore import all_params
from arena.config import NO_VARIATION, RaceConfig, resolve_track
from arena.drivers import LaneFollowerPolicy
from arena.race import RaceResult, run_race
from league.training.rescore import race_log, run_log


@pytest.fixture(scope="module")
def raced() -> tuple[RaceResult, list[dict[str, Any]]]:
    """A real one-car race and the params its reward function was called with."""
    seen: list[dict[str, Any]] = []

    def record(params: dict[str, Any]) -> float:
        seen.append(params)
        return 1.0

    config = RaceConfig.build(
        track="beginner_loop", direction="cw", time_limit_s=5.0, variation=NO_VARIATION
    )
    track, _ = resolve_track(config)
    car = config.cars[0]
    policy = LaneFollowerPolicy(track, car.action_space, speed=1.5)
    return run_race(config, {car.name: policy}, reward_functions=record), seen


def _assert_same(rebuilt: list[dict[str, Any]], seen: list[dict[str, Any]]) -> None:
    # the last step's pose is where the finished car was parked, off the track
    assert len(rebuilt) == len(seen) > 50
    for got, want in zip(rebuilt[:-1], seen[:-1], strict=True):
        assert got.keys() == want.keys()
        for key, value in want.items():
            assert got[key] == (pytest.approx(value, abs=1e-6) if key != "waypoints" else value)


def test_params_rebuilt_from_a_race_trace_are_those_the_race_gave(raced) -> None:
    result, seen = raced
    name = result.config.cars[0].name
    log = race_log(result.to_dict()["config"], result.replay_data(), name)
    _assert_same(all_params(log.document()), seen)


def test_params_rebuilt_from_an_evaluation_simtrace_are_those_the_race_gave(
    raced, tmp_path: Path
) -> None:
    result, seen = raced
    write_evaluation(tmp_path, result)
    data = io.BytesIO()
    with zipfile.ZipFile(data, "w") as archive:
        for path in tmp_path.rglob("*.csv"):
            archive.write(path, path.relative_to(tmp_path).as_posix())
    trains_on = {"track": "beginner_loop", "direction": "cw", "race_type": "time_trial"}
    log = run_log(data.getvalue(), trains_on, None)
    _assert_same(all_params(log.document()), seen)  # a part lap: steps and progress alike
