"""Huber value loss for rsl-rl's PPO, as DeepRacer's ``loss_type: huber`` asks.

rsl-rl's PPO computes the value loss as ``value_loss_coef * mean((v - R)^2)`` (or the
larger of that and its clipped twin). Its gradient with respect to each value is
``2 * c * (v - R) / n``. The Huber loss with threshold ``delta``, scaled to agree with
the squared loss near zero (``2 * c * mean(huber(v - R))``), has gradient
``2 * c * clip(v - R, -delta, delta) / n``: the squared-loss gradient clamped to
``+-2 * c * delta / n``. The critics here add that clamp as a gradient hook on their
output, so PPO's own update trains them with the Huber loss (clipped the same way).
"""

from __future__ import annotations

from typing import Any

import torch
from rsl_rl.models import CNNModel, MLPModel

from agents.hyperparameters import VALUE_LOSS_COEF
from agents.networks import PooledCNNModel

HUBER_DELTA = 1.0


class _HuberValueGradient:
    """Clamp the gradient reaching the value output to the Huber loss's."""

    def forward(self, *args: Any, **kwargs: Any) -> torch.Tensor:
        values = super().forward(*args, **kwargs)  # type: ignore[misc]
        if values.requires_grad:
            bound = 2.0 * VALUE_LOSS_COEF * HUBER_DELTA / values.numel()
            values.register_hook(lambda grad: grad.clamp(-bound, bound))
        return values


class HuberMLPModel(_HuberValueGradient, MLPModel):
    """rsl-rl's ``MLPModel`` as a critic trained with the Huber value loss."""


class HuberCNNModel(_HuberValueGradient, CNNModel):
    """rsl-rl's ``CNNModel`` as a critic trained with the Huber value loss."""


class HuberPooledCNNModel(_HuberValueGradient, PooledCNNModel):
    """``agents.networks.PooledCNNModel`` as a critic trained with the Huber value loss."""
