"""A ``hyperparameters.json`` with ``stack_size`` 3: train, evaluate, resume, pack, race."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from agents import evaluate
from agents.action_spaces import parse_action_space_spec
from agents.cli import app
from agents.hyperparameters import Hyperparameters
from agents.run import Run
from agents.settings import load_settings
from agents.train import Trainer
from arena.config import CarConfig, RaceConfig
from arena.race import run_race
from submissions import load_policy, validate

SPACE = parse_action_space_spec("3x3@1.0")
STACKED = {"num_episodes_between_training": 2, "num_epochs": 2, "stack_size": 3}


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A camera run of two tiny iterations (one evaluation each) with ``stack_size`` 3."""
    tmp = tmp_path_factory.mktemp("stacked")
    hp_file = tmp / "hyperparameters.json"
    hp_file.write_text(json.dumps(STACKED))
    out = tmp / "run"
    args = ["train", "--out", str(out), "--sensors", "camera", "--action-space", "3x3@1.0"]
    args += ["--iterations", "2", "--workers", "0", "--races", "1", "--eval-every", "1"]
    args += ["--eval-time-limit", "2", "--hyperparameters", str(hp_file)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    return out


def test_hyperparameters_take_stack_sizes_1_to_8(tmp_path: Path) -> None:
    path = tmp_path / "hyperparameters.json"
    path.write_text(json.dumps({"stack_size": 3}))
    assert Hyperparameters.load(path).stack_size == 3
    for bad in (0, 9):
        path.write_text(json.dumps({"stack_size": bad}))
        with pytest.raises(ValueError, match="stack_size"):
            Hyperparameters.load(path)


def test_the_packed_model_declares_the_stack(run: Path) -> None:
    assert Run.load(run).stack_size == 3
    report = validate(run / "model" / "model.zip")
    assert report.ok, report.problems
    assert report.info is not None and report.info.stack_size == 3
    assert [s.shape for s in report.info.observation] == [(120, 160, 3)]
    assert len(list(run.glob("evaluation-*/evaluation-simtrace/0-iteration.csv"))) == 2


def test_the_run_evaluates_and_resumes_with_its_stack(run: Path) -> None:
    trained = Run.load(run)
    stacked = trained.evaluation_config(laps=1, time_limit_s=1.0)
    assert [c.stack_size for c in stacked.cars] == [3]
    policy = evaluate.TorchPolicy(trained.actor(), trained.settings.discrete)
    race = evaluate.evaluate_policy(stacked, policy)
    assert race.car("car0").status == "time_up"
    assert Trainer(load_settings(run), run, resume=True, hyperparameters=None).hp.stack_size == 3
    with pytest.raises(ValueError, match="stack_size 1"):
        Trainer(load_settings(run), run, Hyperparameters(), resume=True)
    resumed = CliRunner().invoke(app, ["train", "--out", str(run), "--resume", "--iterations", "1"])
    assert resumed.exit_code == 0, resumed.output
    assert torch.load(run / "checkpoints" / "last.pt", weights_only=True)["iteration"] == 2
    assert validate(run / "model" / "model.zip").info.stack_size == 3


def test_the_stacked_model_races_in_the_league_path(run: Path) -> None:
    policy = load_policy(run / "model" / "model.zip")
    car = CarConfig(name="entry1", sensors=policy.info.sensors, action_space=SPACE, stack_size=3)
    result = run_race(RaceConfig.build(cars=[car], laps=1, time_limit_s=2.0), {"entry1": policy})
    assert result.car("entry1").status == "time_up" and policy.runs > 10


def test_the_commands_evaluate_and_repack_a_stacked_run(run: Path) -> None:
    from slipstream.cli import app as slipstream

    cli = CliRunner()
    shown = cli.invoke(slipstream, ["evaluate", str(run), "--laps", "1", "--time-limit", "2"])
    assert shown.exit_code == 0, shown.output
    out = run.parent / "repacked.zip"
    packed = cli.invoke(slipstream, ["model", "pack", str(run), "--out", str(out)])
    assert packed.exit_code == 0, packed.output
    report = validate(out)
    assert report.ok and report.info is not None and report.info.stack_size == 3


def test_a_clone_reads_as_many_frames_as_its_parent_unless_told(run: Path, tmp_path: Path) -> None:
    """A clone's network must read its parent's frames: without a ``stack_size`` of its own
    (no hyperparameters, or a DeepRacer file without the key) it takes the parent's, and
    trains; one given explicitly stands."""
    settings = load_settings(run)
    assert Trainer(settings, tmp_path / "a", clone=run).hp.stack_size == 3
    lr_only = Trainer(settings, tmp_path / "b", Hyperparameters(lr=1e-3), clone=run)
    assert lr_only.hp.stack_size == 3 and lr_only.hp.lr == 1e-3
    told = Trainer(settings, tmp_path / "c", Hyperparameters(stack_size=1), clone=run)
    assert told.hp.stack_size == 1

    cheap = tmp_path / "hyperparameters.json"  # a DeepRacer file without stack_size
    cheap.write_text(json.dumps({k: v for k, v in STACKED.items() if k != "stack_size"}))
    args = ["train", "--out", str(tmp_path / "d"), "--clone", str(run), "--sensors", "camera"]
    args += ["--action-space", "3x3@1.0", "--iterations", "1", "--workers", "0", "--races", "1"]
    args += ["--eval-every", "1", "--eval-time-limit", "2", "--hyperparameters", str(cheap)]
    cloned = CliRunner().invoke(app, args)
    assert cloned.exit_code == 0, cloned.output
    assert validate(tmp_path / "d" / "model" / "model.zip").info.stack_size == 3
