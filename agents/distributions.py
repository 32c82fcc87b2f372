"""Categorical action distribution for discrete DeepRacer action spaces, pluggable into rsl-rl.

rsl-rl ships only continuous distributions. This one lets its PPO train a policy over a
discrete action list: the MLP outputs ``n`` logits, samples are one-hot rows of length ``n``
(so rsl-rl's rollout storage keeps its ``(num_envs, num_actions)`` float layout) and the env
turns a row back into an action index with ``argmax``.

Plug it in through the actor's config::

    "distribution_cfg": {"class_name": "agents.distributions:CategoricalDistribution"}
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from rsl_rl.modules.distribution import Distribution
from torch import nn


class CategoricalDistribution(Distribution):
    """One-hot categorical distribution over ``output_dim`` discrete actions."""

    def __init__(self, output_dim: int, init_logit_scale: float = 0.01) -> None:
        """Create the distribution.

        Args:
            output_dim: Number of discrete actions (length of each one-hot row).
            init_logit_scale: Gain of the orthogonal init of the MLP's last layer; a small value
                makes the untrained policy close to uniform over the actions.
        """
        if output_dim < 1:
            raise ValueError(
                f"a categorical distribution needs 1 or more actions, got {output_dim}"
            )
        super().__init__(output_dim)
        self.init_logit_scale = init_logit_scale
        self._log_probs: torch.Tensor | None = None

    def update(self, mlp_output: torch.Tensor) -> None:
        """Take the MLP's raw logits as the current distribution."""
        self._log_probs = F.log_softmax(mlp_output.float(), dim=-1)

    def sample(self) -> torch.Tensor:
        """Draw one action per row, returned as a one-hot float row."""
        probs = self._current().exp()
        flat = probs.reshape(-1, self.output_dim)
        index = torch.multinomial(flat, num_samples=1).reshape(probs.shape[:-1])
        return F.one_hot(index, self.output_dim).to(probs.dtype)

    def deterministic_output(self, mlp_output: torch.Tensor) -> torch.Tensor:
        """One-hot row of the most likely action."""
        return _ArgmaxOneHot()(mlp_output)

    def as_deterministic_output_module(self) -> nn.Module:
        """Export-friendly (TorchScript / ONNX) argmax-to-one-hot module."""
        return _ArgmaxOneHot()

    @property
    def input_dim(self) -> int:
        """The MLP outputs one logit per action."""
        return self.output_dim

    @property
    def mean(self) -> torch.Tensor:
        """Expected one-hot row, i.e. the action probabilities."""
        return self._current().exp()

    @property
    def std(self) -> torch.Tensor:
        """Per-component standard deviation of the one-hot row, ``sqrt(p (1 - p))``."""
        probs = self.mean
        return (probs * (1.0 - probs)).sqrt()

    @property
    def entropy(self) -> torch.Tensor:
        """Entropy in nats, one value per row."""
        log_probs = self._current()
        return -(log_probs.exp() * log_probs).sum(dim=-1)

    @property
    def params(self) -> tuple[torch.Tensor, ...]:
        """``(log_probs,)``: normalised logits, enough to rebuild the distribution."""
        return (self._current(),)

    def log_prob(self, outputs: torch.Tensor) -> torch.Tensor:
        """Log-probability of one-hot rows ``outputs`` (a row's weights pick its action)."""
        return (outputs * self._current()).sum(dim=-1)

    def kl_divergence(
        self, old_params: tuple[torch.Tensor, ...], new_params: tuple[torch.Tensor, ...]
    ) -> torch.Tensor:
        """KL(old || new) per row, from two ``params`` tuples."""
        old_log_probs = F.log_softmax(old_params[0], dim=-1)
        new_log_probs = F.log_softmax(new_params[0], dim=-1)
        return (old_log_probs.exp() * (old_log_probs - new_log_probs)).sum(dim=-1)

    def init_mlp_weights(self, mlp: nn.Module) -> None:
        """Shrink the last linear layer so the initial policy is near uniform."""
        last = [module for module in mlp.modules() if isinstance(module, nn.Linear)][-1]
        nn.init.orthogonal_(last.weight, gain=self.init_logit_scale)
        nn.init.zeros_(last.bias)

    def _current(self) -> torch.Tensor:
        if self._log_probs is None:
            raise RuntimeError("CategoricalDistribution.update() must be called before use")
        return self._log_probs


class _ArgmaxOneHot(nn.Module):
    """Maps logits to the one-hot row of their argmax (first index on ties)."""

    def forward(self, logits: torch.Tensor) -> torch.Tensor:
        index = torch.argmax(logits, dim=-1, keepdim=True)
        positions = torch.arange(logits.shape[-1], device=logits.device)
        return (positions == index).to(logits.dtype)
