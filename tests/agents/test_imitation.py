"""Imitation (``--teacher pursuit``): the teacher's actions, a student that learns them, and
runs that resume and clone into PPO."""

from __future__ import annotations

import csv

import pytest
import torch
from typer.testing import CliRunner

import arena
from agents import networks
from agents.action_spaces import parse_action_space_spec
from agents.cli import app
from agents.hyperparameters import Hyperparameters
from agents.imitation import EXPERT_GROUP, imitation_config
from agents.run import Run
from agents.runner import RacingRunner
from agents.settings import TrainSettings
from agents.train import Trainer
from agents.vecenv import RacingVecEnv
from tests.agents.clones import assert_clone_takes_the_actor

CONTINUOUS = parse_action_space_spec("continuous:-30:30:0.5:4")
DISCRETE = parse_action_space_spec("3x3@1.0")
TINY = Hyperparameters(num_episodes_between_training=2, num_epochs=2, batch_size=64)


def _env(space, sensors=("lidar",), workers=0, races=2) -> RacingVecEnv:
    config = arena.make_config(mode="training", action_space=space, sensors=sensors, seed=5)
    return RacingVecEnv(config, "pursuit", num_races=races, num_workers=workers, expert=True)


def test_driving_the_teachers_actions_laps_the_track():
    """The expert group is the pure-pursuit driver's action for each car: fed back as the
    actions (from worker processes), both cars complete a lap."""
    env = _env(CONTINUOUS, workers=2)
    try:
        obs = env.get_observations()
        for _ in range(150):
            obs, *_ = env.step(obs[EXPERT_GROUP])
        episodes = env.pop_episodes()
    finally:
        env.close()
    assert sum(e["lap_complete"] for e in episodes) >= 2, episodes


def test_a_discrete_teacher_gives_one_hot_rows():
    env = _env(DISCRETE)
    try:
        rows = env.get_observations()[EXPERT_GROUP]
    finally:
        env.close()
    assert rows.shape == (2, DISCRETE.n)
    assert torch.equal(rows.sum(dim=1), torch.ones(2)) and set(rows.unique().tolist()) == {0, 1}


def test_a_discrete_student_learns_the_teachers_action_not_its_own():
    """Where the teacher picks another action than the student's most likely one, an update
    moves the student to the teacher's action (cross-entropy on the teacher's labels)."""
    env = _env(DISCRETE)
    try:
        actor, critic, groups = networks.model_configs("dense 256-256", ("lidar",), DISCRETE)
        hp = Hyperparameters(num_epochs=4, batch_size=8)
        steps = 4
        cfg = imitation_config(hp.to_rsl_rl(env.num_envs, actor, critic, groups, steps), True)
        alg = RacingRunner(env, cfg, log_dir=None, device="cpu").alg
        obs = env.get_observations()
    finally:
        env.close()

    def probabilities() -> torch.Tensor:
        alg.student(obs, stochastic_output=True)
        return alg.student.distribution.mean.detach()

    before = probabilities()
    taught = (before.argmax(dim=1) + 1) % DISCRETE.n  # never the student's own choice
    obs[EXPERT_GROUP] = torch.nn.functional.one_hot(taught, DISCRETE.n).float()
    for _ in range(steps):
        alg.act(obs)
        alg.process_env_step(obs, torch.zeros(env.num_envs), torch.zeros(env.num_envs), {})
    alg.update()
    after = probabilities()
    rows = torch.arange(env.num_envs)
    assert (after[rows, taught] > before[rows, taught]).all(), (before, after, taught)
    assert torch.equal(after.argmax(dim=1), taught), (after, taught)


def _student_and_teacher(
    actor: torch.nn.Module, steps: int = 300
) -> tuple[torch.Tensor, torch.Tensor]:
    """The student's greedy actions and the teacher's (samples x (steering, speed)), in the
    states the student drives into in two races."""
    env = _env(CONTINUOUS, sensors=("camera",), races=2)
    student, teacher = [], []
    try:
        obs = env.get_observations()
        for _ in range(steps):
            with torch.inference_mode():
                action = actor(obs)
            student.append(action)
            teacher.append(obs[EXPERT_GROUP])
            obs, *_ = env.step(action)
    finally:
        env.close()
    return torch.cat(student), torch.cat(teacher)


@pytest.mark.slow
def test_a_camera_student_learns_what_the_teacher_does_where_it_drives(tmp_path):
    """After 12 short iterations the student reads the road: its speed is much closer to
    the teacher's than the best constant speed (the teacher's mean, error 1.0 of the
    variance) would be, and it steers the way the teacher steers. Measured on DeepRacer's
    car, seeds 0-5 on one thread: speed error 0.20-0.36 of the teacher's variance,
    steering correlation 0.47-0.72. The steering, which lags and which the teacher leads,
    comes later: its error, 0.52-1.15 of its variance, is too spread over seeds and
    machines to bound."""
    settings = TrainSettings(
        action_space=CONTINUOUS,
        sensors=("camera",),
        reward_fn="pursuit",
        teacher="pursuit",
        workers=0,
        races=2,
        iterations=12,
        steps_per_env=256,
        eval_every=1000,
        eval_time_limit=5.0,
    )
    hp = Hyperparameters(num_epochs=5, batch_size=64, lr=1e-3)
    Trainer(settings, tmp_path / "run", hp).run()
    student, teacher = _student_and_teacher(Run.load(tmp_path / "run").actor())
    speed_error = ((student[:, 1] - teacher[:, 1]) ** 2).mean() / teacher[:, 1].var()
    assert speed_error < 0.6, float(speed_error)
    steering = torch.corrcoef(torch.stack([student[:, 0], teacher[:, 0]]))[0, 1]
    assert steering > 0.3, float(steering)


def test_episodes_the_teacher_drives_lap_where_a_fresh_student_does_not(tmp_path):
    """``teacher_drives``: the teacher's actions drive that share of the episodes (the
    student still learns from every state). Driven by it, both cars of a fresh run lap
    the loop in the first rollout; the untrained student drives off the road."""

    def first_rollout(share: float) -> dict[str, str]:
        settings = TrainSettings(
            action_space=CONTINUOUS, sensors=("lidar",), teacher="pursuit", teacher_drives=share,
            workers=0, races=2, iterations=1, steps_per_env=200, eval_every=1000,
        )  # fmt: skip
        Trainer(settings, tmp_path / str(share), TINY).run()
        with (tmp_path / str(share) / "metrics.csv").open(newline="") as handle:
            return next(csv.DictReader(handle))

    assert float(first_rollout(1.0)["lap_completion"]) == 1.0
    assert float(first_rollout(0.0)["lap_completion"]) == 0.0
    with pytest.raises(ValueError, match="--teacher-drives needs --teacher"):
        TrainSettings(action_space=CONTINUOUS, teacher_drives=0.5)


def test_an_imitation_run_resumes_and_clones_into_ppo(tmp_path):
    base = {
        "action_space": DISCRETE,
        "sensors": ("lidar",),
        "workers": 0,
        "races": 1,
        "iterations": 1,
        "eval_every": 1000,
        "eval_time_limit": 5.0,
    }
    taught = TrainSettings(**base, teacher="pursuit")
    run = tmp_path / "taught"
    result = Trainer(taught, run, TINY).run()
    assert result.model_zip is not None and result.model_zip.exists()
    ckpt = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert "actor_state_dict" in ckpt and "critic_state_dict" not in ckpt
    with (run / "metrics.csv").open(newline="") as handle:
        row = next(csv.DictReader(handle))
    assert float(row["imitation_loss"]) > 0 and row["value_loss"] == ""

    Trainer(taught, run, TINY, resume=True).run()  # student and optimizer, strict
    assert torch.load(run / "checkpoints" / "last.pt", weights_only=True)["iteration"] == 1

    ppo = Trainer(TrainSettings(**base), tmp_path / "ppo", TINY, clone=run)
    assert_clone_takes_the_actor(ppo, run)  # the student as the actor, a fresh critic


def test_cli_names_the_teachers_it_knows(tmp_path):
    args = ["train", "--out", str(tmp_path / "run"), "--sensors", "lidar", "--iterations", "1"]
    result = CliRunner().invoke(app, [*args, "--teacher", "nobody"])
    assert result.exit_code == 2 and "pursuit" in result.output
