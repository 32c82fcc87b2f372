"""DeepRacer's model_metadata.json and hyperparameters.json read as DeepRacer reads them.

The metadata's sensors are trained unless ``--sensors`` disagrees (an error naming both);
a SAC file is refused with a sentence saying PPO is what runs; hyperparameter keys
DeepRacer does not know are warned about and ignored.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from agents.hyperparameters import Hyperparameters
from agents.options import settings_from_options
from agents.settings import TrainSettings
from slipstream.cli import app

DISCRETE = [
    {"steering_angle": -20.0, "speed": 1.0, "index": 0},
    {"steering_angle": 0.0, "speed": 1.5, "index": 1},
    {"steering_angle": 20.0, "speed": 1.0, "index": 2},
]
CONTINUOUS = {"steering_angle": {"low": -30.0, "high": 30.0}, "speed": {"low": 0.5, "high": 3.0}}


def _metadata(tmp_path: Path, **keys: object) -> Path:
    path = tmp_path / "model_metadata.json"
    path.write_text(json.dumps({"action_space": DISCRETE, **keys}))
    return path


def _settings(action_space: Path | str, sensors: str | None = None) -> TrainSettings:
    options = {"action_space": str(action_space), "sensors": sensors, "iterations": 1}
    return settings_from_options(options)


def test_the_metadata_files_sensors_are_trained(tmp_path: Path) -> None:
    meta = _metadata(tmp_path, sensor=["FRONT_FACING_CAMERA", "LIDAR"])
    settings = _settings(meta)
    assert settings.sensors == ("camera", "lidar")


def test_agreeing_sensors_are_accepted_in_any_order(tmp_path: Path) -> None:
    meta = _metadata(tmp_path, sensor=["FRONT_FACING_CAMERA", "LIDAR"])
    settings = _settings(meta, "lidar,camera")
    assert set(settings.sensors) == {"camera", "lidar"}


def test_a_file_without_sensor_means_deepracers_camera(tmp_path: Path) -> None:
    settings = _settings(_metadata(tmp_path))
    assert settings.sensors == ("camera",)


def test_without_a_metadata_file_the_default_is_the_camera(tmp_path: Path) -> None:
    assert _settings("3x3@1.0").sensors == ("camera",)


def test_conflicting_sensors_are_an_error_naming_both(tmp_path: Path) -> None:
    meta = _metadata(tmp_path, sensor=["LIDAR"])
    args = ["train", "--out", str(tmp_path / "run"), "--iterations", "1"]
    result = CliRunner().invoke(app, [*args, "--action-space", str(meta), "--sensors", "camera"])
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert "--sensors camera conflicts" in text and "['LIDAR']" in text
    assert not (tmp_path / "run").exists()


def test_sac_is_refused_saying_ppo_is_what_runs(tmp_path: Path) -> None:
    path = tmp_path / "model_metadata.json"
    sac = {"action_space": CONTINUOUS, "action_space_type": "continuous"}
    path.write_text(json.dumps(sac | {"training_algorithm": "sac"}))
    args = ["train", "--out", str(tmp_path / "run"), "--iterations", "1"]
    result = CliRunner().invoke(app, [*args, "--action-space", str(path)])
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert "'sac'" in text and "clipped PPO only" in text
    assert not (tmp_path / "run").exists()


def test_unknown_hyperparameter_keys_are_ignored_and_named(tmp_path: Path) -> None:
    path = tmp_path / "hyperparameters.json"
    path.write_text(json.dumps({"lr": 0.001, "learning_rate": 0.1, "num_epochs": 3, "x": 1}))
    hp, ignored = Hyperparameters.read(path)
    assert hp.lr == 0.001 and hp.num_epochs == 3
    assert ignored == ["learning_rate", "x"]


def test_a_known_hyperparameter_with_a_bad_value_is_named(tmp_path: Path) -> None:
    path = tmp_path / "hyperparameters.json"
    path.write_text(json.dumps({"num_epochs": "many"}))
    with pytest.raises(ValueError, match="num_epochs"):
        Hyperparameters.read(path)
    path.write_text("[1, 2]")
    with pytest.raises(ValueError, match="JSON object"):
        Hyperparameters.read(path)


@pytest.mark.slow
def test_a_lidar_metadata_file_trains_a_lidar_model(tmp_path: Path) -> None:
    """The measured bug: a LIDAR file used to train camera-only; now the run is LIDAR."""
    meta = _metadata(tmp_path, sensor=["LIDAR"])
    hp = tmp_path / "hyperparameters.json"
    tiny = {"num_episodes_between_training": 2, "num_epochs": 2, "learning_rate": 0.1}
    hp.write_text(json.dumps(tiny))
    run = tmp_path / "run"
    args = ["train", "--out", str(run), "--action-space", str(meta), "--hyperparameters", str(hp)]
    args += ["--iterations", "1", "--workers", "0", "--eval-time-limit", "5"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "ignoring learning_rate" in " ".join(result.output.split())
    written = json.loads((run / "model" / "model_metadata.json").read_text())
    assert written["sensor"] == ["LIDAR"]
    stored = json.loads((run / "training_settings.json").read_text())
    assert stored["sensors"] == ["lidar"]
    assert stored["grow_batch"] is False  # an explicit file is honoured as written
