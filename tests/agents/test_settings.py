"""TrainSettings: one declaration the ``train`` command's options are generated from."""

from __future__ import annotations

import inspect

import pytest
import typer
from pydantic import ValidationError
from typer.core import TyperOption

from agents.action_spaces import parse_action_space_spec
from agents.cli import app, train
from agents.hyperparameters import Hyperparameters
from agents.options import PYTHON_ONLY, option_names, settings_from_options
from agents.settings import (
    RESUME_OVERRIDES,
    TrainSettings,
    grows_batch,
    load_settings,
    overlapped,
    save_settings,
)

SPACE = parse_action_space_spec("3x3@1.0")
NOT_SETTINGS = {"out", "recipe", "list_recipes", "clone", "resume", "hyperparameters"}
# Options whose command-line form differs from the field's type (agents.options).
PARSED = {"sensors", "action_space", "opponent", "paced_rivals", "also_tracks"}


def _train_options() -> dict[str, TyperOption]:
    command = typer.main.get_command(app).commands["train"]
    return {p.name: p for p in command.params if isinstance(p, TyperOption)}


def test_every_field_is_documented():
    for name, field in TrainSettings.model_fields.items():
        assert field.description, name


def test_train_options_are_the_settings_fields_by_name_with_their_docs():
    options = _train_options()
    assert set(inspect.signature(train).parameters) == set(options) | {"ctx"}
    assert set(options) - NOT_SETTINGS == set(option_names())
    assert set(TrainSettings.model_fields) - set(option_names()) == set(PYTHON_ONLY)
    for name, option in options.items():
        if name in NOT_SETTINGS:
            continue
        field = TrainSettings.model_fields[name]  # KeyError: an option renamed on the way
        assert option.help == field.description, name
        if name not in PARSED:
            assert option.default == field.default, name
    assert set(RESUME_OVERRIDES) <= set(options)


def test_command_line_forms_map_to_the_fields(tmp_path, monkeypatch):
    reward = tmp_path / "reward.py"
    reward.write_text("def reward_function(params):\n    return 1.0\n")
    monkeypatch.chdir(tmp_path)
    options = {
        "sensors": "camera, lidar",
        "action_space": "3x3@1.0",
        "reward_fn": "reward.py",
        "opponent": ["a.onnx"],
        "paced_rivals": "0.7, 1",
        "iterations": 3,
    }
    settings = settings_from_options(options)
    assert settings.paced_rivals == (0.7, 1.0)
    assert settings.sensors == ("camera", "lidar") and settings.action_space == SPACE
    assert settings.reward_fn == str(reward.resolve())
    assert settings.opponent == (str(tmp_path / "a.onnx"),)
    assert settings.iterations == 3


def test_paced_rivals_default_to_four_shares_and_none_turns_them_off():
    assert settings_from_options({}).paced_rivals == (0.6, 0.8, 0.9, 1.0)
    assert settings_from_options({"paced_rivals": "none"}).paced_rivals == ()
    with pytest.raises(ValueError, match="--paced-rivals takes comma-separated shares"):
        settings_from_options({"paced_rivals": "fast"})
    with pytest.raises(
        ValidationError, match=r"share of the learner's pace is in \(0, 1\], got 1.2"
    ):
        settings_from_options({"paced_rivals": "0.8,1.2"})


def test_also_tracks_are_comma_separated_and_need_a_race_each():
    settings = settings_from_options(
        {"track": "slipstream_speedway", "also_tracks": "grand_tour, hairpin_hollow"}
    )
    assert settings.also_tracks == ("grand_tour", "hairpin_hollow")
    assert settings_from_options({}).also_tracks == ()
    with pytest.raises(ValidationError, match="named twice"):
        settings_from_options({"track": "grand_tour", "also_tracks": "grand_tour"})
    with pytest.raises(ValidationError, match=r"3 tracks need at least 3 races.*--races 3"):
        settings_from_options({"also_tracks": "grand_tour,slipstream_speedway", "races": 2})


def test_resume_keeps_the_run_settings_but_the_overrides(tmp_path):
    from agents import cli

    save_settings(tmp_path, TrainSettings(action_space=SPACE, seed=7, minutes=30.0, threads=2))
    settings = cli._settings(tmp_path, None, None, True, {"iterations": 2, "seed": 1})
    assert settings.seed == 7 and settings.action_space == SPACE
    assert settings.iterations == 2 and settings.minutes is None
    assert settings.threads is None  # auto, on the machine that resumes


def test_settings_round_trip(tmp_path):
    settings = TrainSettings(action_space=SPACE, sensors=("lidar",), opponent=("/m.zip",))
    save_settings(tmp_path, settings)
    assert load_settings(tmp_path) == settings


def test_new_runs_store_their_preset_by_name(tmp_path):
    from agents.run import Run

    settings = TrainSettings(action_space=SPACE, sensors=("camera",), workers=0)
    Run(tmp_path, settings, Hyperparameters()).write()
    assert load_settings(tmp_path).network == "CPU CNN"


def test_unknown_fields_are_refused():
    with pytest.raises(ValidationError, match="no_such_field"):
        TrainSettings(action_space=SPACE, no_such_field=1)


@pytest.mark.parametrize(("grow_batch", "device", "steps_per_env", "grows"), [
    (None, "cuda", None, True),  # auto: a GPU grows the iteration with the races
    (None, "cuda:1", None, True),
    (None, "cpu", None, False),
    (None, "cuda", 256, False),  # a fixed rollout length is kept as given
    (True, "cpu", None, True),
    (False, "cuda", None, False),
])  # fmt: skip
def test_the_batch_grows_on_a_gpu_unless_told(grow_batch, device, steps_per_env, grows):
    assert grows_batch(grow_batch, device, steps_per_env) is grows


@pytest.mark.parametrize(("sync", "device", "overlaps"), [
    (None, "cuda", True),  # auto: the update runs on the GPU while the cores collect
    (None, "cpu", False),  # auto: on CPU cores the two halves compete for the same cores
    (False, "cpu", True),
    (True, "cuda", False),
])  # fmt: skip
def test_collection_and_update_overlap_on_a_gpu_unless_told(sync, device, overlaps):
    assert overlapped(sync, device) is overlaps


def test_a_race_type_s_own_settings_reach_its_training_and_evaluation_races(tmp_path):
    from agents.run import Run
    from agents.train import Trainer
    from arena.config import BotConfig

    options = {"race_type": "head_to_bot", "bots": 2, "bot_speed": 1.5, "sensors": "lidar"}
    settings = settings_from_options({**options, "iterations": 1, "workers": 0})
    trainer = Trainer(settings, tmp_path / "run", Hyperparameters())
    env, _ = trainer._make_env()
    env.close()
    assert env.config.bots == BotConfig(count=2, speed=1.5)
    trainer.target.write()
    evaluation = Run.load(tmp_path / "run").evaluation_config()
    assert evaluation.bots == BotConfig(count=2, speed=1.5)
    # evaluated as another race type, it takes that type's own defaults
    assert Run.load(tmp_path / "run").evaluation_config(race_type="time_trial").bots is None
    boxes = settings_from_options({"race_type": "object_avoidance", "boxes": 3})
    assert boxes.race_rules()["obstacles"].count == 3


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"race_type": "time_trial", "boxes": 3}, "boxes: only object_avoidance races"),
        ({"race_type": "object_avoidance", "bot_speed": 1.0}, "bot_speed: only head_to_bot"),
        ({"race_type": "head_to_bot", "bots": 9}, "bots: Input should be less than or equal to 6"),
        (
            {"race_type": "head_to_bot", "bot_lane_change_min_s": 6},
            "bot_lane_change_min_s must not exceed bot_lane_change_max_s",
        ),
    ],
)
def test_race_settings_of_another_type_or_out_of_range_are_refused_by_name(options, message):
    with pytest.raises(ValidationError, match=message):
        settings_from_options(options)
