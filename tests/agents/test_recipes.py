"""Recipes (``slipstream train --recipe``): listed, applied, overridden, recorded in the run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from agents import cli
from agents.action_spaces import parse_action_space_spec
from agents.cli import app
from agents.options import option_names
from agents.recipes import RECIPES, get_recipe
from agents.run import Run
from arena.config import RACE_TYPES


def test_every_race_type_has_a_recipe_whose_options_are_train_options():
    assert set(RACE_TYPES) <= set(RECIPES)
    for name, recipe in RECIPES.items():
        assert recipe.name == name
        assert set(recipe.options) <= set(option_names()), name
        settings = recipe.settings()  # the options parse: specs, sensors, samples
        assert settings.recipe == name
        assert settings.race_type == recipe.options["race_type"]
        recipe.hyperparameters_model()  # DeepRacer keys in range
        assert recipe.parent is None or recipe.parent in RECIPES


def test_camera_recipes_read_two_frames_as_the_parents_they_clone():
    """The camera-only recipes stack two frames (DeepRacer's ``stack_size``), and a recipe
    that clones another's run reads as many as its parent: a clone needs its network."""
    for name in ("time_trial", "head_to_model", "head_to_model_ppo"):
        assert get_recipe(name).hyperparameters_model().stack_size == 2, name
    for recipe in RECIPES.values():
        if recipe.parent is not None:
            frames = recipe.hyperparameters_model().stack_size
            assert frames == get_recipe(recipe.parent).hyperparameters_model().stack_size


def test_list_recipes_shows_each_one_without_needing_out():
    result = CliRunner().invoke(app, ["train", "--list-recipes"])
    assert result.exit_code == 0, result.output
    for name in RECIPES:
        assert name in result.output


def test_an_unknown_recipe_is_refused_naming_the_recipes(tmp_path):
    args = ["train", "--recipe", "fastest", "--out", str(tmp_path / "r"), "--minutes", "1"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    assert "fastest" in result.output and "first_laps" in result.output
    assert not (tmp_path / "r").exists()


def test_explicit_options_win_over_the_recipe(tmp_path):
    recipe = get_recipe("time_trial")
    given = {"track": "slipstream_speedway", "seed": 3, "iterations": 2}
    settings = cli._settings(tmp_path / "r", "time_trial", None, False, given)
    assert settings.track == "slipstream_speedway" and settings.seed == 3
    assert settings.teacher == "pursuit" and settings.reward_fn == recipe.options["reward_fn"]
    assert settings.action_space == parse_action_space_spec(recipe.options["action_space"])
    assert settings.workers == recipe.options["workers"] and settings.recipe == "time_trial"


def test_head_to_model_needs_a_parent_run_and_races_its_model(tmp_path):
    with pytest.raises(ValueError, match="--clone"):
        cli._settings(tmp_path / "r", "head_to_model", None, False, {"minutes": 1.0})
    parent = tmp_path / "parent"
    with pytest.raises(ValueError, match=r"model\.zip"):
        cli._settings(tmp_path / "r", "head_to_model", parent, False, {"minutes": 1.0})
    (parent / "model").mkdir(parents=True)
    (parent / "model" / "model.zip").write_bytes(b"zip")
    settings = cli._settings(tmp_path / "r", "head_to_model", parent, False, {"minutes": 1.0})
    assert settings.opponent == (str((parent / "model" / "model.zip").resolve()),)
    assert settings.selfplay == "pool"
    # paced racers the teacher passes, unless the user names others
    assert settings.paced_rivals == (0.6, 0.65, 0.7, 0.75)
    given = {"minutes": 1.0, "paced_rivals": "0.8,1"}
    settings = cli._settings(tmp_path / "r", "head_to_model", parent, False, given)
    assert settings.paced_rivals == (0.8, 1.0)


def test_ppo_after_head_to_model_imitation_is_anchored_and_races_the_imitation_model(tmp_path):
    imitation = tmp_path / "imitation"
    (imitation / "model").mkdir(parents=True)
    (imitation / "model" / "model.zip").write_bytes(b"zip")
    given = {"minutes": 1.0}
    settings = cli._settings(tmp_path / "r", "head_to_model_ppo", imitation, False, given)
    assert settings.opponent == (str((imitation / "model" / "model.zip").resolve()),)
    assert settings.teacher is None and settings.anchor == "pursuit"
    assert settings.selfplay == "pool" and settings.paced_rivals
    head_to_model = get_recipe("head_to_model").settings()
    for same in ("track", "sensors", "action_space", "preset"):  # what a clone must keep
        assert getattr(settings, same) == getattr(head_to_model, same), same


@pytest.mark.slow
def test_train_with_a_recipe_applies_and_records_it(tmp_path):
    run = tmp_path / "quick"
    hp_file = tmp_path / "hp.json"
    hp_file.write_text(json.dumps({"num_episodes_between_training": 2, "num_epochs": 1}))
    args = ["train", "--recipe", "first_laps", "--out", str(run), "--iterations", "1"]
    args += ["--sensors", "lidar", "--eval-time-limit", "2", "--hyperparameters", str(hp_file)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    trained = Run.load(run)
    s = trained.settings
    assert s.recipe == "first_laps" and s.sensors == ("lidar",)  # --sensors won
    assert s.eval_time_limit == 2.0 and s.eval_every == 4 and s.races == 1  # recipe's
    assert s.action_space == parse_action_space_spec("3x3@1.0")
    # An explicit hyperparameters.json replaces the recipe's: DeepRacer's discount, not 0.99.
    recipe_discount = get_recipe("first_laps").hyperparameters["discount_factor"]
    assert trained.hyperparameters.num_epochs == 1
    assert trained.hyperparameters.discount_factor != recipe_discount
    stored = json.loads((run / "training_settings.json").read_text())
    assert stored["recipe"] == "first_laps"


@pytest.mark.slow
def test_a_recipe_brings_its_hyperparameters(tmp_path):
    run = tmp_path / "quick"
    args = ["train", "--recipe", "first_laps", "--out", str(run), "--iterations", "1"]
    args += ["--sensors", "lidar", "--eval-time-limit", "2"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    hp = Run.load(run).hyperparameters
    expected = get_recipe("first_laps").hyperparameters_model()
    assert hp == expected and hp.discount_factor == 0.99 and hp.num_epochs == 2


def test_resume_refuses_a_recipe(tmp_path):
    with pytest.raises(ValueError, match="--recipe"):
        cli._settings(Path(tmp_path), "time_trial", None, True, {})
