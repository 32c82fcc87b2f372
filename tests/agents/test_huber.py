"""The Huber value loss: PPO's squared-error gradient reaches the critic clamped to Huber's."""

from __future__ import annotations

import pytest
import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from agents.huber import HUBER_DELTA, HuberMLPModel
from agents.hyperparameters import VALUE_LOSS_COEF, Hyperparameters


def critics() -> tuple[MLPModel, HuberMLPModel, TensorDict]:
    torch.manual_seed(0)
    obs = TensorDict({"lidar": torch.rand(32, 8)}, batch_size=[32])
    groups = {"critic": ["lidar"]}
    plain = MLPModel(obs, groups, "critic", 1, hidden_dims=[16], activation="relu")
    huber = HuberMLPModel(obs, groups, "critic", 1, hidden_dims=[16], activation="relu")
    huber.load_state_dict(plain.state_dict())
    return plain, huber, obs


def test_squared_loss_through_the_huber_critic_trains_like_the_huber_loss() -> None:
    plain, huber, obs = critics()
    # Returns far from some values and close to others: both Huber regimes are used.
    returns = torch.linspace(-4.0, 4.0, 32).unsqueeze(1)
    # What rsl-rl's PPO computes, through the Huber critic ...
    (VALUE_LOSS_COEF * (huber(obs) - returns).pow(2).mean()).backward()
    # ... against the Huber loss itself, scaled to match the squared loss near zero.
    values = plain(obs)
    errors = (values - returns).abs()
    assert (errors > HUBER_DELTA).any() and (errors < HUBER_DELTA).any()
    expected = torch.nn.functional.huber_loss(values, returns, delta=HUBER_DELTA)
    (2.0 * VALUE_LOSS_COEF * expected).backward()
    for (name, a), b in zip(huber.named_parameters(), plain.parameters(), strict=True):
        assert torch.allclose(a.grad, b.grad, atol=1e-6), name


def test_values_are_unchanged_and_inference_needs_no_hook() -> None:
    plain, huber, obs = critics()
    assert torch.equal(plain(obs), huber(obs))
    with torch.inference_mode():
        assert torch.equal(plain(obs), huber(obs))


@pytest.mark.parametrize(
    ("loss_type", "cls"),
    [("huber", "agents.huber:HuberMLPModel"), ("mean squared error", "MLPModel")],
)
def test_loss_type_picks_the_critic(loss_type: str, cls: str) -> None:
    critic = {"class_name": "MLPModel", "hidden_dims": [256, 256]}
    cfg = Hyperparameters(loss_type=loss_type).to_rsl_rl(1, {}, critic, {})
    assert cfg["critic"]["class_name"] == cls
    assert critic["class_name"] == "MLPModel"  # the caller's config is not changed
