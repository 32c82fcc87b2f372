"""Self-play opponents: run on the submissions runner (non-finite outputs zeroed), raced
in a head-to-model run's evaluations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.action_spaces import parse_action_space_spec
from agents.evaluate import EvalSummary, evaluate_policy, evaluation_config, run_opponent
from agents.selfplay import opponent_policy, pursuit_lap_s
from agents.settings import TrainSettings
from arena.pursuit import racing_line_for
from submissions import OnnxRunner
from tests.submissions.test_runner import identity
from tracks.catalog import get_track


def test_opponents_drive_greedily_and_zero_non_finite_outputs() -> None:
    discrete = opponent_policy(identity(3), discrete=True, name="snapshot:4")
    assert isinstance(discrete, OnnxRunner) and discrete.non_finite == "zero"
    assert discrete.act({"lidar": np.array([0.1, 0.7, 0.2], np.float32)}) == 1
    assert discrete.act({"lidar": [0.1, math.nan, 0.2]}) == 2
    continuous = opponent_policy(identity(2), discrete=False)
    action = continuous.act({"lidar": [math.inf, -3.0]})
    assert action.dtype == np.float32
    np.testing.assert_array_equal(action, [0.0, -1.0])


class _Throttle:
    """Drives straight at a fixed throttle in ``[-1, 1]`` (continuous actions)."""

    def __init__(self, throttle: float) -> None:
        self.action = np.array([0.0, throttle], np.float32)

    def reset(self) -> None:
        """Stateless."""

    def act(self, observation):
        return self.action


def test_evaluation_races_the_opponent_in_the_other_cars() -> None:
    """A head-to-model evaluation drives the opponent, not the policy, in car1."""
    space = parse_action_space_spec("continuous:-30:30:0.5:4")
    config = evaluation_config(
        "beginner_loop", "head_to_model", ("lidar",), space, laps=1, time_limit_s=1.5
    )
    fast, slow = _Throttle(1.0), _Throttle(-1.0)
    raced = evaluate_policy(config, fast, opponent=slow)
    assert raced.car("car0").distance > 1.5 * raced.car("car1").distance
    alone = evaluate_policy(config, fast)  # no opponent: the policy races itself
    assert alone.car("car1").distance > 1.5 * raced.car("car1").distance


def test_a_head_to_model_run_evaluates_against_its_first_opponent(tmp_path) -> None:
    parent = tmp_path / "parent.onnx"
    parent.write_bytes(identity(2))
    space = parse_action_space_spec("continuous:-30:30:0.5:4")
    run = TrainSettings(
        race_type="head_to_model", sensors=("lidar",), action_space=space, opponent=(str(parent),)
    )
    assert isinstance(run_opponent(run), OnnxRunner)
    assert run_opponent(run.model_copy(update={"race_type": "time_trial"})) is None
    camera = run.model_copy(update={"sensors": ("camera",)})
    with pytest.raises(ValueError, match="reads lidar, which this run's cars do not have"):
        run_opponent(camera)


def test_paced_racers_are_scaled_by_the_pursuit_drivers_own_laps() -> None:
    """Its mean lap from a standing start: slower than the racing line's limit lap (it
    starts standing and its steering lags), within a fifth of it."""
    space = parse_action_space_spec("continuous:-30:30:0.5:4")
    trial = evaluation_config("slipstream_speedway", "time_trial", ("lidar",), space, laps=2)
    limit = racing_line_for(get_track("slipstream_speedway")).lap_time
    lap = pursuit_lap_s(trial)
    assert lap is not None and limit < lap < 1.2 * limit
    stopped = evaluation_config(
        "slipstream_speedway", "time_trial", ("lidar",), space, laps=2, time_limit_s=5.0
    )
    assert pursuit_lap_s(stopped) is None  # no lap in 5 s: nothing to scale by


def test_a_learners_pace_is_its_mean_lap_else_its_best() -> None:
    finished = EvalSummary(3, 100.0, 9.0, 30.0, 0, 0, 0, "finished")
    assert finished.pace_lap == 10.0
    unfinished = EvalSummary(1, 50.0, 11.0, None, 2, 0, 0, "time_limit")
    assert unfinished.pace_lap == 11.0
    assert EvalSummary(0, 40.0, None, None, 1, 0, 0, "time_limit").pace_lap is None
