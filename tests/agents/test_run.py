"""The run object: a run folder read once (settings, hyperparameters, reward, race, model)."""

from __future__ import annotations

import pytest

from agents.action_spaces import parse_action_space_spec
from agents.hyperparameters import Hyperparameters
from agents.run import Run, holds_run
from agents.settings import TrainSettings

SPACE = parse_action_space_spec("3x3@1.0")


def _settings(**changes) -> TrainSettings:
    return TrainSettings(action_space=SPACE, sensors=("lidar",), workers=0, **changes)


def test_a_written_run_loads_back_with_its_settings_and_hyperparameters(tmp_path):
    hp = Hyperparameters(stack_size=2, batch_size=32)
    Run(tmp_path, _settings(seed=5, track="slipstream_speedway"), hp).write()
    run = Run.load(tmp_path)
    assert run.settings.seed == 5 and run.settings.network == "dense 256-256"  # by name
    assert run.hyperparameters == hp and run.stack_size == 2
    assert not holds_run(tmp_path)  # settings alone: no metrics or checkpoint yet
    config = run.evaluation_config()
    assert config.track == "slipstream_speedway" and config.seed == 5
    assert [car.stack_size for car in config.cars] == [2]
    assert run.evaluation_config(laps=1, track="beginner_loop").track == "beginner_loop"


def test_evaluations_race_the_further_tracks_only_when_asked(tmp_path):
    also = {"track": "slipstream_speedway", "also_tracks": ("grand_tour", "beginner_loop")}
    alone = Run(tmp_path / "a", _settings(**also), Hyperparameters())
    assert [c.track for c in alone.evaluation_configs()] == ["slipstream_speedway"]
    every = Run(tmp_path / "b", _settings(eval_also_tracks=True, seed=4, **also), Hyperparameters())
    configs = every.evaluation_configs()
    assert [c.track for c in configs] == ["slipstream_speedway", "grand_tour", "beginner_loop"]
    assert {(c.seed, c.laps, c.race_type) for c in configs} == {(4, 3, "time_trial")}


def test_a_folder_without_a_run_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="holds no training run"):
        Run.load(tmp_path / "nothing")


def test_the_reward_is_resolved_once_per_run(tmp_path):
    log = tmp_path / "loads.txt"
    reward = tmp_path / "reward.py"
    reward.write_text(
        f"open({str(log)!r}, 'a').write('loaded\\n')\n"
        "def reward_function(params):\n    return 1.0\n"
    )
    run = Run(tmp_path / "run", _settings(reward_fn=str(reward)), Hyperparameters())
    first = run.reward
    loads = log.read_text().count("loaded")  # its smoke test and a fresh copy to train with
    assert run.reward is first and first({}) == 1.0
    assert log.read_text().count("loaded") == loads
