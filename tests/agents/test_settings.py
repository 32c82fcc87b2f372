"""TrainSettings: one declaration the ``train`` command maps one to one; old files still load."""

from __future__ import annotations

import inspect
import json

import pytest
import typer
from pydantic import ValidationError
from typer.core import TyperOption

from agents.action_spaces import parse_action_space_spec
from agents.cli import app, train
from agents.settings import RESUME_OVERRIDES, TrainSettings, load_settings, save_settings

SPACE = parse_action_space_spec("3x3@1.0")
NOT_SETTINGS = {"out", "clone", "resume", "hyperparameters"}
# Options whose command-line form differs from the field's type (parsed by agents.cli).
PARSED = {"sensors", "action_space", "opponent"}


def _train_options() -> dict[str, TyperOption]:
    command = typer.main.get_command(app).commands["train"]
    return {p.name: p for p in command.params if isinstance(p, TyperOption)}


def test_every_field_is_documented():
    for name, field in TrainSettings.model_fields.items():
        assert field.description, name


def test_train_options_are_the_settings_fields_by_name_with_their_docs():
    options = _train_options()
    assert set(inspect.signature(train).parameters) == set(options)
    for name, option in options.items():
        if name in NOT_SETTINGS:
            continue
        field = TrainSettings.model_fields[name]  # KeyError: an option renamed on the way
        assert option.help == field.description, name
        if name not in PARSED:
            assert option.default == field.default, name
    assert set(RESUME_OVERRIDES) <= set(options)


def test_command_line_forms_map_to_the_fields(tmp_path, monkeypatch):
    from agents import cli

    reward = tmp_path / "reward.py"
    reward.write_text("def reward_function(params):\n    return 1.0\n")
    monkeypatch.chdir(tmp_path)
    options = {
        name: TrainSettings.model_fields[name].default
        for name in TrainSettings.model_fields
        if name in _train_options()
    }
    options.update(
        sensors="camera, lidar",
        action_space="3x3@1.0",
        reward_fn="reward.py",
        opponent=["a.onnx"],
        iterations=3,
    )
    settings = cli._settings(tmp_path / "run", False, options)
    assert settings.sensors == ("camera", "lidar") and settings.action_space == SPACE
    assert settings.reward_fn == str(reward.resolve())
    assert settings.opponent == (str(tmp_path / "a.onnx"),)
    assert settings.iterations == 3


def test_resume_keeps_the_run_settings_but_the_overrides(tmp_path):
    from agents import cli

    save_settings(tmp_path, TrainSettings(action_space=SPACE, seed=7, minutes=30.0, threads=2))
    options = dict.fromkeys(TrainSettings.model_fields) | {"iterations": 2, "threads": 1}
    settings = cli._settings(tmp_path, True, options)
    assert settings.seed == 7 and settings.action_space == SPACE
    assert settings.iterations == 2 and settings.minutes is None and settings.threads == 1


def test_settings_round_trip(tmp_path):
    settings = TrainSettings(action_space=SPACE, sensors=("lidar",), opponent=("/m.zip",))
    save_settings(tmp_path, settings)
    assert load_settings(tmp_path) == settings


def test_settings_files_with_the_former_field_names_still_load(tmp_path):
    current = TrainSettings(
        action_space=SPACE,
        reward_fn="/r.py",
        opponent=("/m.zip",),
        eval_time_limit=9.0,
        network="CPU CNN",
    )
    data = json.loads(current.model_dump_json())
    for old, new in (
        ("reward", "reward_fn"),
        ("opponents", "opponent"),
        ("eval_time_limit_s", "eval_time_limit"),
    ):
        data[old] = data.pop(new)
    (tmp_path / "training_settings.json").write_text(json.dumps(data))
    assert load_settings(tmp_path) == current


def test_camera_runs_stored_without_a_preset_keep_the_former_default(tmp_path):
    """Such runs were trained when the camera default was the 3-layer CNN."""
    save_settings(tmp_path, TrainSettings(action_space=SPACE, sensors=("camera",)))
    assert load_settings(tmp_path).network == "3-layer CNN"
    save_settings(tmp_path, TrainSettings(action_space=SPACE, sensors=("lidar",)))
    assert load_settings(tmp_path).preset == "dense 256-256"


def test_new_runs_store_their_preset_by_name(tmp_path):
    from agents.train import Trainer

    settings = TrainSettings(action_space=SPACE, sensors=("camera",), workers=0)
    Trainer(settings, tmp_path)._write_run_files()
    assert load_settings(tmp_path).network == "CPU CNN"


def test_unknown_fields_are_refused():
    with pytest.raises(ValidationError, match="no_such_field"):
        TrainSettings(action_space=SPACE, no_such_field=1)
