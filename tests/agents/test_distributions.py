"""CategoricalDistribution: agreement with torch's Categorical and a PPO smoke test."""

from __future__ import annotations

import torch
from rsl_rl.runners import OnPolicyRunner
from torch.distributions import Categorical

from agents.distributions import CategoricalDistribution
from tests.agents.bandit import Bandit, ppo_config

CLASS_NAME = "agents.distributions:CategoricalDistribution"


def _dist(logits: torch.Tensor) -> CategoricalDistribution:
    dist = CategoricalDistribution(logits.shape[-1])
    dist.update(logits)
    return dist


def test_log_prob_entropy_kl_match_torch() -> None:
    gen = torch.Generator().manual_seed(0)
    old_logits = 3.0 * torch.randn(64, 7, generator=gen)
    new_logits = 3.0 * torch.randn(64, 7, generator=gen)
    index = torch.randint(0, 7, (64,), generator=gen)
    one_hot = torch.nn.functional.one_hot(index, 7).float()
    old, new = _dist(old_logits), _dist(new_logits)
    reference_old, reference_new = Categorical(logits=old_logits), Categorical(logits=new_logits)

    torch.testing.assert_close(old.log_prob(one_hot), reference_old.log_prob(index))
    torch.testing.assert_close(old.entropy, reference_old.entropy())
    torch.testing.assert_close(
        old.kl_divergence(old.params, new.params),
        torch.distributions.kl_divergence(reference_old, reference_new),
    )
    torch.testing.assert_close(old.mean, reference_old.probs)


def test_samples_are_one_hot_with_right_frequencies() -> None:
    torch.manual_seed(1)
    probs = torch.tensor([0.1, 0.6, 0.3])
    dist = _dist(probs.log().expand(20_000, 3))
    samples = dist.sample()
    assert samples.shape == (20_000, 3)
    assert torch.all(samples.sum(dim=-1) == 1.0)
    assert torch.all((samples == 0.0) | (samples == 1.0))
    # 20k draws: the standard error of each frequency is below 0.0035, so 0.015 is > 4 sigma.
    torch.testing.assert_close(samples.mean(dim=0), probs, atol=0.015, rtol=0.0)


def test_deterministic_output_is_argmax_one_hot() -> None:
    logits = torch.tensor([[0.1, 2.0, -1.0], [5.0, 4.0, 3.0], [0.0, 0.0, 1.0]])
    dist = CategoricalDistribution(3)
    expected = torch.eye(3)[[1, 0, 2]]
    assert torch.equal(dist.deterministic_output(logits), expected)
    assert torch.equal(dist.as_deterministic_output_module()(logits), expected)


def test_rsl_rl_ppo_learns_a_bandit_with_it(capsys) -> None:
    torch.manual_seed(0)
    env = Bandit(num_envs=64)
    config = ppo_config(CLASS_NAME, epochs=4, save_interval=1000)
    runner = OnPolicyRunner(env, config, log_dir=None, device="cpu")
    actor = runner.alg.get_policy()
    assert isinstance(actor.distribution, CategoricalDistribution)
    obs = env.get_observations()
    start = actor(obs, stochastic_output=True)
    assert torch.all(start.sum(dim=-1) == 1.0)
    assert actor.output_entropy.mean() > 1.0  # near uniform (log 3 = 1.0986) before training

    runner.learn(10)
    capsys.readouterr()  # the runner prints progress; keep test output quiet
    greedy = runner.get_inference_policy()(obs)
    assert torch.all(greedy.argmax(dim=-1) == 2)
    actor(obs, stochastic_output=True)
    assert actor.output_distribution_params[0].exp()[:, 2].mean() > 0.9
