"""A PPO rollout collected in two staggered halves of the env workers.

In rsl-rl's lock-step rollout each control step is the learner's forward pass for every
slot, then every worker's step: the workers wait while the learner acts, and the learner
waits while they step. :func:`collect_staggered` splits the workers in two halves
(:attr:`agents.vecenv.RacingVecEnv.halves`) and acts for one half while the other's
workers step, so the learner's forward passes and bookkeeping run beside the races.

Every stored transition is what the lock-step rollout stores: slot k's observation,
action, value, log-probability, reward and done of step t, from the same policy, in the
same order. Only the forward passes are on half batches, and PPO's
``process_env_step`` (the return scale, the storage) still sees whole steps.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from tensordict import TensorDict

# What a half's step returns: the next observations, rewards, dones and extras.
HalfStep = tuple[TensorDict, torch.Tensor, torch.Tensor, dict[str, Any]]


def collect_staggered(
    alg: Any,
    env: Any,
    obs: TensorDict,
    steps: int,
    device: str,
    check: Callable[[TensorDict, torch.Tensor, torch.Tensor], None],
    record: Callable[[torch.Tensor, torch.Tensor, dict[str, Any]], None],
) -> TensorDict:
    """``steps`` steps of every slot into ``alg``'s storage, from observations ``obs``;
    returns the observations after the last step.

    ``alg`` is an rsl-rl PPO (``act``, ``process_env_step``, its ``transition``), ``env``
    a :class:`~agents.vecenv.RacingVecEnv` with :attr:`~agents.vecenv.RacingVecEnv.halves`.
    ``check(obs, rewards, dones)`` sees each half's step as it arrives, before the policy
    acts on it (rsl-rl's NaN check); ``record(rewards, dones, extras)`` each whole step
    once it is stored (rsl-rl's logger).
    """
    halves = env.halves
    rows = [env.slots_of(half) for half in halves]
    half_obs = [obs[r] for r in rows]
    acted: list[Any] = [None, None]  # each half's transition, acted, waiting for its step

    def act(h: int) -> None:
        alg.transition = type(alg.transition)()
        actions = alg.act(half_obs[h])
        acted[h] = alg.transition
        env.send_step(halves[h], actions.to(env.device))

    def receive(h: int) -> HalfStep:
        next_obs, rewards, dones, extras = env.receive_step(halves[h])
        check(next_obs, rewards, dones)
        half_obs[h] = next_obs.to(device)
        return half_obs[h], rewards.to(device), dones.to(device), extras

    act(0)
    for t in range(steps):
        act(1)  # while the first half's workers step
        first = acted[0], receive(0)
        if t + 1 < steps:
            act(0)  # while the second half's workers step
        second = acted[1], receive(1)
        record(*_store_step(alg, first, second))
    alg.transition = type(alg.transition)()
    return torch.cat(half_obs)


def _store_step(
    alg: Any, first: tuple[Any, HalfStep], second: tuple[Any, HalfStep]
) -> tuple[torch.Tensor, torch.Tensor, dict[str, Any]]:
    """PPO's record of one whole step from its two halves; its rewards, dones, extras."""
    a, (obs_a, rewards_a, dones_a, extras_a) = first
    b, (obs_b, rewards_b, dones_b, extras_b) = second
    whole = type(alg.transition)()
    whole.observations = torch.cat([a.observations, b.observations])
    whole.actions = torch.cat([a.actions, b.actions])
    whole.values = torch.cat([a.values, b.values])
    whole.actions_log_prob = torch.cat([a.actions_log_prob, b.actions_log_prob])
    whole.distribution_params = tuple(
        torch.cat(pair) for pair in zip(a.distribution_params, b.distribution_params, strict=True)
    )
    whole.hidden_states = a.hidden_states  # (None, None): the networks are not recurrent
    alg.transition = whole
    obs = torch.cat([obs_a, obs_b])
    rewards, dones = torch.cat([rewards_a, rewards_b]), torch.cat([dones_a, dones_b])
    extras = _merged_extras(extras_a, extras_b)
    alg.process_env_step(obs, rewards, dones, extras)
    return rewards, dones, extras


def _merged_extras(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """The extras of two halves' steps as one step's: time-outs in slot order, the ended
    episodes' logs together."""
    merged: dict[str, Any] = {"time_outs": torch.cat([a["time_outs"], b["time_outs"]])}
    logs = [e["log"] for e in (a, b) if "log" in e]
    if logs:
        keys = logs[0].keys()
        merged["log"] = {k: torch.cat([log[k] for log in logs]) for k in keys}
    return merged
