"""rsl-rl's PPO learning from rewards scaled by the running spread of the return.

:class:`ReturnScaledPPO` divides the rewards PPO learns from by a running standard deviation
of the discounted return, so values and returns stay of order 1 whatever the reward's scale
(a reward paying speed in the hundreds per step gave value losses near 1e6 before). rsl-rl
5.5 normalises observations and advantages, not returns.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from rsl_rl.algorithms import PPO
from tensordict import TensorDict

from agents.fused_adam import fuse_adam

RETURN_SCALE_CLIP = 10.0  # scaled rewards are clipped to +-this (early, tiny-variance steps)


class ReturnScale(torch.nn.Module):
    """Rewards divided by the running standard deviation of each slot's discounted return.

    The statistics are Python floats (cheap per step), saved as the module's extra state.
    """

    def __init__(self, gamma: float) -> None:
        super().__init__()
        self.gamma = gamma
        self.count, self.mean, self.var = 1e-4, 0.0, 1.0
        self.returns: torch.Tensor | None = None  # per slot, not saved

    def forward(self, rewards: torch.Tensor, dones: torch.Tensor) -> torch.Tensor:
        """Update the statistics with this step's returns; the scaled rewards."""
        if self.returns is None or self.returns.shape != rewards.shape:
            self.returns = torch.zeros_like(rewards, dtype=torch.float64)
        self.returns = self.returns * self.gamma + rewards
        var, mean = torch.var_mean(self.returns, unbiased=False)
        self._update(float(mean), float(var), self.returns.numel())
        self.returns = self.returns.masked_fill(dones.view_as(self.returns).bool(), 0.0)
        scaled = rewards / math.sqrt(self.var + 1e-8)
        return scaled.clamp(-RETURN_SCALE_CLIP, RETURN_SCALE_CLIP)

    def _update(self, mean: float, var: float, n: int) -> None:
        """Merge a batch's mean and variance into the running ones (Chan et al.)."""
        delta, total = mean - self.mean, self.count + n
        m2 = self.var * self.count + var * n + delta * delta * self.count * n / total
        self.mean += delta * n / total
        self.var, self.count = m2 / total, total

    def get_extra_state(self) -> dict[str, float]:
        """The running statistics, for the module's state dict."""
        return {"count": self.count, "mean": self.mean, "var": self.var}

    def set_extra_state(self, state: dict[str, float]) -> None:
        """Restore the running statistics."""
        self.count, self.mean, self.var = state["count"], state["mean"], state["var"]


class ReturnScaledPPO(PPO):
    """rsl-rl's PPO learning from rewards scaled by :class:`ReturnScale`.

    The scale's statistics are saved with the algorithm (``return_scale_state_dict``) and
    loaded with the critic; a checkpoint without them starts fresh statistics.
    """

    def __init__(self, *args: Any, scale_returns: bool = True, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        fuse_adam(self.optimizer)
        self.return_scale = ReturnScale(self.gamma).to(self.device) if scale_returns else None

    def process_env_step(
        self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict
    ) -> None:
        """PPO's step record, with scaled rewards."""
        if self.return_scale is not None:
            rewards = self.return_scale(rewards, dones)
        super().process_env_step(obs, rewards, dones, extras)

    def save(self) -> dict:
        """PPO's state dicts and the return scale's."""
        state = super().save()
        if self.return_scale is not None:
            state["return_scale_state_dict"] = self.return_scale.state_dict()
        return state

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        """PPO's load; the return scale too when the critic is loaded and it was saved."""
        result = super().load(loaded_dict, load_cfg, strict)
        fuse_adam(self.optimizer)
        saved = loaded_dict.get("return_scale_state_dict")
        if self.return_scale is not None and saved and (load_cfg or {"critic": 1}).get("critic"):
            self.return_scale.load_state_dict(saved)
        return result
