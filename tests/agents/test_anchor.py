"""PPO after imitation (``agents.anchor``): the critic warms up with the actor held, and the
anchor pulls the actor toward the teacher with a weight that decays to nothing."""

from __future__ import annotations

import pytest
import torch

from agents.action_spaces import parse_action_space_spec
from agents.evaluate import EvalSummary
from agents.hyperparameters import Hyperparameters
from agents.imitation import EXPERT_GROUP
from agents.run import Run
from agents.settings import TrainSettings
from agents.train import CLONE_CRITIC_WARMUP, Trainer

CONTINUOUS = parse_action_space_spec("continuous:-30:30:0.5:4")
TINY = Hyperparameters(num_episodes_between_training=2, num_epochs=2, batch_size=64)
QUICK = Hyperparameters(num_episodes_between_training=2, num_epochs=5, batch_size=64, lr=1e-3)
BASE = {
    "action_space": CONTINUOUS,
    "sensors": ("lidar",),
    "reward_fn": "pursuit",
    "workers": 0,
    "races": 1,
    "steps_per_env": 128,
    "eval_every": 1000,
    "eval_time_limit": 5.0,
}


def _actor_weights(run) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in Run.load(run).actor().state_dict().items()}


@pytest.fixture(scope="module")
def taught(tmp_path_factory):
    """A one-iteration imitation run of the pursuit driver."""
    run = tmp_path_factory.mktemp("anchor") / "taught"
    Trainer(TrainSettings(**BASE, teacher="pursuit", iterations=1), run, TINY).run()
    return run


def test_a_clone_of_an_imitation_run_warms_its_critic_up_by_default(taught, tmp_path):
    ppo = TrainSettings(**BASE, iterations=1)
    assert Trainer(ppo, tmp_path / "clone", TINY, clone=taught)._critic_warmup() == (
        CLONE_CRITIC_WARMUP
    )
    assert Trainer(ppo, tmp_path / "fresh", TINY)._critic_warmup() == 0
    told = TrainSettings(**BASE, iterations=1, critic_warmup=2)
    assert Trainer(told, tmp_path / "told", TINY, clone=taught)._critic_warmup() == 2


def test_the_actor_is_held_while_the_critic_warms_up_and_moves_after(taught, tmp_path):
    parent = _actor_weights(taught)
    held = TrainSettings(**BASE, iterations=2, critic_warmup=2)
    result = Trainer(held, tmp_path / "held", TINY, clone=taught).run()
    assert result.iterations == 2
    after_warmup = _actor_weights(tmp_path / "held")
    assert all(torch.equal(after_warmup[k], v) for k, v in parent.items())
    critic = torch.load(tmp_path / "held" / "checkpoints" / "last.pt", weights_only=True)
    assert "critic_state_dict" in critic

    moved = TrainSettings(**BASE, iterations=1, critic_warmup=0)
    Trainer(moved, tmp_path / "moved", TINY, clone=taught).run()
    after = _actor_weights(tmp_path / "moved")
    assert any(not torch.equal(after[k], v) for k, v in parent.items())


def test_evaluations_in_the_critic_warm_up_are_not_kept_as_the_run_s_best(
    taught, tmp_path, monkeypatch
):
    """The warm-up races the parent's actor: its evaluations, however good, are not this
    run's model (the PPO stage packed its imitation parent unchanged, RESULTS.md)."""
    perfect = EvalSummary(3, 100.0, 8.0, 24.0, 0, 0, 0, "finished")
    worse = EvalSummary(3, 100.0, 9.0, 30.0, 1, 0, 1, "finished")
    scripted = [perfect, perfect, worse]  # iterations 0 and 1 warm the critic up
    monkeypatch.setattr(Trainer, "_evaluate", lambda trainer, runner: scripted.pop(0))
    settings = TrainSettings(**{**BASE, "eval_every": 1}, iterations=3, critic_warmup=2)
    Trainer(settings, tmp_path / "ppo", TINY, clone=taught).run()
    assert not scripted
    for which in ("best", "fastest"):
        kept = torch.load(tmp_path / "ppo" / "checkpoints" / f"{which}.pt", weights_only=True)
        assert kept["iteration"] == 2, which
    moved = _actor_weights(tmp_path / "ppo")  # the packed model is the actor after warm-up
    parent = _actor_weights(taught)
    assert any(not torch.equal(moved[k], v) for k, v in parent.items())


def _distance_to_teacher(trainer: Trainer, iterations: int) -> tuple[list[float], float]:
    """Train ``iterations`` iterations by hand; the anchor weights the updates used, and the
    mean squared distance of the actor's action to the teacher's over the last rollout."""
    env, _ = trainer._make_env()
    try:
        runner = trainer._make_runner(env)
        runner.start()
        weights = [runner.iteration(it).get("anchor_weight", 0.0) for it in range(iterations)]
        observations = runner.alg.storage.observations.flatten(0, 1)
        with torch.inference_mode():
            actions = runner.alg.actor(observations)
        distance = float(((actions - observations[EXPERT_GROUP]) ** 2).mean())
    finally:
        env.close()
    return weights, distance


def test_the_anchor_pulls_the_actor_to_the_teacher_with_a_decaying_weight(tmp_path):
    """Measured: the anchored actor's distance to the teacher is 0.39-0.62 of PPO's alone
    after 6 iterations (seeds 0-2)."""
    torch.manual_seed(0)
    anchored = TrainSettings(
        **BASE, iterations=6, anchor="pursuit", anchor_weight=5.0, anchor_iterations=8
    )
    weights, near = _distance_to_teacher(Trainer(anchored, tmp_path / "a", QUICK), 6)
    assert weights == pytest.approx([5.0, 4.375, 3.75, 3.125, 2.5, 1.875])
    torch.manual_seed(0)
    # Weight 0: PPO alone, on the same rollouts (the teacher's actions observed, unused).
    plain = TrainSettings(**BASE, iterations=6, anchor="pursuit", anchor_weight=0.0)
    weights, far = _distance_to_teacher(Trainer(plain, tmp_path / "p", QUICK), 6)
    assert weights == [0.0] * 6
    assert near < 0.8 * far, (near, far)


def test_the_anchor_holds_its_weight_unless_told_to_decay(tmp_path):
    held = TrainSettings(**BASE, iterations=2, anchor="pursuit", anchor_weight=2.0)
    weights, _ = _distance_to_teacher(Trainer(held, tmp_path / "h", TINY), 2)
    assert weights == [2.0, 2.0]


def test_anchor_and_teacher_cannot_both_be_given():
    with pytest.raises(ValueError, match="--anchor"):
        TrainSettings(**BASE, teacher="pursuit", anchor="pursuit")


def _rollout_noise(trainer: Trainer) -> float:
    """The std of the actions a one-iteration run sampled around its actor's mean (the
    actor held by the critic's warm-up, so the mean is the one the rollout drew from)."""
    env, _ = trainer._make_env()
    try:
        runner = trainer._make_runner(env)
        trainer._load_weights(runner)
        runner.start()
        runner.iteration(0)
        observations = runner.alg.storage.observations.flatten(0, 1)
        with torch.inference_mode():
            means = runner.alg.actor(observations)
        return float((runner.alg.storage.actions.flatten(0, 1) - means).std())
    finally:
        env.close()


def test_min_std_keeps_the_action_noise_of_ppo_after_imitation_at_its_floor(taught, tmp_path):
    """The imitation student's noise is 0.1 and PPO after it shrank it to 0.034 in 45
    iterations (benchmarks/RESULTS.md); ``min_std`` is the floor its rollouts sample at."""
    held = {**BASE, "iterations": 1, "critic_warmup": 1}
    floored = Trainer(TrainSettings(**held, min_std=0.3), tmp_path / "f", TINY, clone=taught)
    assert 0.25 < _rollout_noise(floored) < 0.35
    plain = Trainer(TrainSettings(**held), tmp_path / "p", TINY, clone=taught)
    assert _rollout_noise(plain) < 0.13


def test_min_std_is_refused_with_a_discrete_action_space():
    discrete = {**BASE, "action_space": parse_action_space_spec("3x3@1.0")}
    with pytest.raises(ValueError, match="--min-std"):
        TrainSettings(**discrete, min_std=0.1)
