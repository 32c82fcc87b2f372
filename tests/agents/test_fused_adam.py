"""Adam fused into one kernel per step: the same steps as torch's default, kept on resume."""

from __future__ import annotations

import copy

import torch

from agents.fused_adam import fuse_adam
from agents.hyperparameters import PPO_CLASS
from agents.runner import RacingRunner
from tests.agents.bandit import Bandit, ppo_config


def _trained(fused: bool) -> list[torch.Tensor]:
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(1, 4, 3), torch.nn.Flatten(), torch.nn.Linear(144, 2))
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-2)
    if fused:
        fuse_adam(optimizer)
        assert optimizer.param_groups[0]["fused"] is True
    x, y = torch.randn(16, 1, 8, 8), torch.randn(16, 2)
    for _ in range(50):
        optimizer.zero_grad()
        ((net(x) - y) ** 2).mean().backward()
        optimizer.step()
    return [p.detach() for p in net.parameters()]


def test_fused_adam_takes_the_steps_torch_default_takes():
    for fused, default in zip(_trained(True), _trained(False), strict=True):
        torch.testing.assert_close(fused, default, rtol=1e-5, atol=1e-6)


def _ppo_runner() -> RacingRunner:
    cfg = ppo_config("GaussianDistribution")
    cfg["algorithm"]["class_name"] = PPO_CLASS
    return RacingRunner(Bandit(), cfg, log_dir=None, device="cpu", sync=True)


def test_training_and_resuming_from_an_unfused_checkpoint_use_the_fused_update():
    trained = _ppo_runner()
    assert trained.alg.optimizer.param_groups[0]["fused"] is True
    trained.learn(2)
    saved = trained.alg.save()
    # A checkpoint written before the switch: its groups say "not fused", its steps are
    # CPU scalars.
    old = copy.deepcopy(saved)
    for group in old["optimizer_state_dict"]["param_groups"]:
        group["fused"] = None
    resumed = _ppo_runner()
    resumed.alg.load(old, None, strict=True)
    assert all(g["fused"] is True for g in resumed.alg.optimizer.param_groups)
    steps = [s["step"] for s in resumed.alg.optimizer.state.values()]
    assert steps and all(s.dtype == torch.float32 and float(s) > 0 for s in steps)
    resumed.learn(2)  # the fused kernel steps from the loaded moments
    assert all(torch.isfinite(p).all() for p in resumed.alg.actor.parameters())
