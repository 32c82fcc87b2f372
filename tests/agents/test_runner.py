"""RacingRunner: rsl-rl's PPO one iteration at a time, NaN check, no files of its own."""

from __future__ import annotations

import math

import pytest

from agents.runner import NonFiniteEnvError, RacingRunner
from tests.agents.bandit import Bandit, ppo_config

STEPS = 8


def _cfg(check_for_nan: bool = True) -> dict:
    return ppo_config("GaussianDistribution", steps=STEPS, check_for_nan=check_for_nan)


def test_iterations_return_losses_and_log_only_tensorboard(tmp_path, capsys):
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=str(tmp_path), device="cpu")
    runner.start()
    losses = [runner.iteration(it) for it in (4, 5)]
    assert env.steps == 2 * STEPS
    assert all(set(loss) == {"value", "surrogate", "entropy"} for loss in losses)
    assert runner.current_learning_iteration == 5
    runner.logger.writer.flush()
    files = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()}
    assert files and all(name.startswith("events.out.tfevents.") for name in files), files
    assert capsys.readouterr().out == ""


def test_learn_runs_that_many_iterations_from_start():
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu")
    runner.learn(3)
    assert env.steps == 3 * STEPS


def test_iteration_needs_start():
    runner = RacingRunner(Bandit(), _cfg(), log_dir=None, device="cpu")
    with pytest.raises(RuntimeError, match="start"):
        runner.iteration(0)


def test_nan_from_the_env_stops_training_naming_the_iteration():
    runner = RacingRunner(Bandit(nan_at_step=STEPS + 3), _cfg(), log_dir=None, device="cpu")
    runner.start()
    runner.iteration(7)
    with pytest.raises(NonFiniteEnvError, match=r"^iteration 8: The rewards .* NaN"):
        runner.iteration(8)


def test_nan_check_follows_the_config_switch():
    env = Bandit(nan_at_step=3)
    cfg = _cfg(check_for_nan=False)
    cfg["algorithm"].update(num_learning_epochs=1, num_mini_batches=1)  # one step on the NaN
    runner = RacingRunner(env, cfg, log_dir=None, device="cpu")
    runner.start()
    losses = runner.iteration(0)
    assert env.steps == STEPS and math.isnan(losses["value"])
