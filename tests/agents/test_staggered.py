"""Staggered collection: the learner acts for half the workers' races while the other half
step, and stores the rollout the lock-step collection stores."""

from __future__ import annotations

import pytest
import torch

import arena
from agents import networks
from agents.hyperparameters import Hyperparameters
from agents.runner import RacingRunner
from agents.vecenv import RacingVecEnv
from arena.actions import default_discrete_space

# Discrete: a forward pass on half the slots rounds differently from one on all of them
# (the matrix kernels differ by batch size), which a sampled action index absorbs where a
# continuous action would carry it into the physics.
SPACE = default_discrete_space()
SENSORS = ("lidar",)
STEPS = 40  # each slot's steps an iteration: long enough for cars to bump and restart


def _runner(stagger: bool, workers: int = 2, races: int = 2) -> RacingRunner:
    """PPO on two-car head-to-model races of learners (every car a slot), privileged critic,
    its weights drawn from seed 0."""
    config = arena.make_config(
        track="beginner_loop",  # narrow: untrained cars leave it and restart
        race_type="head_to_model",
        num_cars=2,
        sensors=SENSORS,
        action_space=SPACE,
        mode="training",
        seed=11,
    )
    env = RacingVecEnv(config, "pursuit", num_races=races, num_workers=workers, privileged=True)
    actor, critic, groups = networks.model_configs("dense 256-256", SENSORS, SPACE, "privileged")
    torch.manual_seed(0)
    hp = Hyperparameters(batch_size=32, num_epochs=2)
    cfg = hp.to_rsl_rl(env.num_envs, actor, critic, groups, STEPS)
    return RacingRunner(env, cfg, log_dir=None, device="cpu", threads=1, sync=True, stagger=stagger)


def _iterate(runner: RacingRunner, iterations: int) -> dict[str, torch.Tensor]:
    """Seeded iterations; the last rollout's storage and the actor's weights after it."""
    torch.manual_seed(0)
    try:
        runner.start()
        for it in range(iterations):
            runner.iteration(it)
        st = runner.alg.storage
        stored = {
            "observations": st.observations["lidar"].clone(),
            "privileged": st.observations[networks.PRIVILEGED_GROUP].clone(),
            "actions": st.actions.clone(),
            "rewards": st.rewards.clone(),
            "dones": st.dones.clone(),
            "values": st.values.clone(),
            "log_prob": st.actions_log_prob.clone(),
        }
        weights = {f"actor.{k}": v.clone() for k, v in runner.alg.actor.state_dict().items()}
        return {**stored, **weights}
    finally:
        runner.env.close()


@pytest.mark.slow
def test_staggered_collection_stores_what_lock_step_stores():
    """Two iterations with two workers, staggered and in lock-step from the same seeds: the
    same observations, actions, rewards and dones in the same slots and steps, the same
    values and log-probabilities and weights after the updates (to rounding)."""
    staggered_runner = _runner(stagger=True)
    assert staggered_runner.staggered
    staggered = _iterate(staggered_runner, 2)
    lock_step_runner = _runner(stagger=False)
    assert not lock_step_runner.staggered
    lock_step = _iterate(lock_step_runner, 2)
    assert staggered["dones"].any(), "no episode ended: the cars did not meet the rules"
    for name in ("observations", "privileged", "actions", "rewards", "dones"):
        assert torch.equal(staggered[name], lock_step[name]), name
    for name, tensor in lock_step.items():
        torch.testing.assert_close(staggered[name], tensor, rtol=1e-4, atol=1e-5, msg=name)


def test_one_worker_or_none_collects_in_lock_step():
    """Staggering needs two workers to split; imitation (no critic) always steps in turn."""
    for workers in (0, 1):
        runner = _runner(stagger=True, workers=workers)
        try:
            assert not runner.staggered
        finally:
            runner.env.close()
