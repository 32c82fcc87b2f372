"""A three-armed bandit as an rsl-rl ``VecEnv`` and a small PPO config, for runner tests."""

from __future__ import annotations

import math

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict


class Bandit(VecEnv):
    """One-step episodes; action 2 of 3 pays 1, the others 0. ``nan_at_step`` poisons
    that step's first reward; ``steps`` counts the env steps taken."""

    def __init__(self, num_envs: int = 16, nan_at_step: int | None = None) -> None:
        self.num_envs = num_envs
        self.num_actions = 3
        self.max_episode_length = 1
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long)
        self.device = "cpu"
        self.cfg = {}
        self.steps = 0
        self.nan_at_step = nan_at_step

    def get_observations(self) -> TensorDict:
        return TensorDict({"policy": torch.ones(self.num_envs, 2)}, batch_size=[self.num_envs])

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        assert actions.shape == (self.num_envs, 3)
        rewards = (actions.argmax(dim=-1) == 2).float()
        if self.steps == self.nan_at_step:
            rewards[0] = math.nan
        self.steps += 1
        dones = torch.ones(self.num_envs, dtype=torch.bool)
        return self.get_observations(), rewards, dones, {"log": {"/episode/reward": 1.0}}


def ppo_config(distribution: str, steps: int = 8, epochs: int = 2, **extra: object) -> dict:
    """rsl-rl's runner config: a 16-unit MLP actor with ``distribution`` and critic, PPO
    with ``epochs`` learning epochs over ``steps`` steps per env; ``extra`` keys added."""
    model = {"class_name": "MLPModel", "hidden_dims": [16], "activation": "elu"}
    return {
        "num_steps_per_env": steps,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "multi_gpu": None,
        "logger": "tensorboard",
        "algorithm": {
            "class_name": "PPO",
            "learning_rate": 3e-3,
            "num_learning_epochs": epochs,
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
        "actor": {**model, "distribution_cfg": {"class_name": distribution}},
        "critic": model,
        **extra,
    }
