"""RacingRunner: rsl-rl's PPO one iteration at a time, NaN check, no files of its own."""

from __future__ import annotations

import math

import pytest
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from agents.runner import NonFiniteEnvError, RacingRunner

STEPS = 8


class _Bandit(VecEnv):
    """Three actions, the last one pays; ``nan_at_step`` poisons one step's rewards."""

    def __init__(self, nan_at_step: int | None = None) -> None:
        self.num_envs = 16
        self.num_actions = 3
        self.max_episode_length = 1
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long)
        self.device = "cpu"
        self.cfg = {}
        self.steps = 0
        self.nan_at_step = nan_at_step

    def get_observations(self) -> TensorDict:
        return TensorDict({"policy": torch.ones(self.num_envs, 2)}, batch_size=[self.num_envs])

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        rewards = (actions.argmax(dim=-1) == 2).float()
        if self.steps == self.nan_at_step:
            rewards[0] = math.nan
        self.steps += 1
        dones = torch.ones(self.num_envs, dtype=torch.bool)
        return self.get_observations(), rewards, dones, {"log": {"/episode/reward": 1.0}}


def _cfg(check_for_nan: bool = True) -> dict:
    model = {"class_name": "MLPModel", "hidden_dims": [16], "activation": "elu"}
    return {
        "num_steps_per_env": STEPS,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "multi_gpu": None,
        "logger": "tensorboard",
        "check_for_nan": check_for_nan,
        "algorithm": {
            "class_name": "PPO",
            "learning_rate": 3e-3,
            "num_learning_epochs": 2,
            "num_mini_batches": 2,
            "clip_param": 0.2,
            "gamma": 0.99,
            "lam": 0.95,
            "entropy_coef": 0.0,
            "value_loss_coef": 1.0,
            "max_grad_norm": 1.0,
            "schedule": "fixed",
            "desired_kl": 0.01,
        },
        "actor": {**model, "distribution_cfg": {"class_name": "GaussianDistribution"}},
        "critic": model,
    }


def test_iterations_return_losses_and_log_only_tensorboard(tmp_path, capsys):
    env = _Bandit()
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
    env = _Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu")
    runner.learn(3)
    assert env.steps == 3 * STEPS


def test_iteration_needs_start():
    runner = RacingRunner(_Bandit(), _cfg(), log_dir=None, device="cpu")
    with pytest.raises(RuntimeError, match="start"):
        runner.iteration(0)


def test_nan_from_the_env_stops_training_naming_the_iteration():
    runner = RacingRunner(_Bandit(nan_at_step=STEPS + 3), _cfg(), log_dir=None, device="cpu")
    runner.start()
    runner.iteration(7)
    with pytest.raises(NonFiniteEnvError, match=r"^iteration 8: The rewards .* NaN"):
        runner.iteration(8)


def test_nan_check_follows_the_config_switch():
    env = _Bandit(nan_at_step=3)
    cfg = _cfg(check_for_nan=False)
    cfg["algorithm"].update(num_learning_epochs=1, num_mini_batches=1)  # one step on the NaN
    runner = RacingRunner(env, cfg, log_dir=None, device="cpu")
    runner.start()
    losses = runner.iteration(0)
    assert env.steps == STEPS and math.isnan(losses["value"])
