"""RacingRunner: rsl-rl's PPO one iteration at a time, NaN check, no files of its own."""

from __future__ import annotations

import math

import pytest
import torch

from agents.runner import NonFiniteEnvError, RacingRunner, thread_counts
from tests.agents.bandit import Bandit, ppo_config

STEPS = 8


def _cfg(check_for_nan: bool = True) -> dict:
    return ppo_config("GaussianDistribution", steps=STEPS, check_for_nan=check_for_nan)


def test_iterations_return_losses_and_log_only_tensorboard(tmp_path, capsys):
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=str(tmp_path), device="cpu")
    runner.start()
    losses = [runner.iteration(it) for it in (4, 5)]
    assert env.steps == 2 * STEPS
    assert all(set(loss) == {"value", "surrogate", "entropy"} for loss in losses)
    assert runner.current_learning_iteration == 5
    runner.logger.writer.flush()
    files = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()}
    assert files and all(name.startswith("events.out.tfevents.") for name in files), files
    assert capsys.readouterr().out == ""


def test_learn_runs_that_many_iterations_from_start():
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu")
    runner.learn(3)
    assert env.steps == 3 * STEPS


def test_iteration_needs_start():
    runner = RacingRunner(Bandit(), _cfg(), log_dir=None, device="cpu")
    with pytest.raises(RuntimeError, match="start"):
        runner.iteration(0)


def test_nan_from_the_env_stops_training_naming_the_iteration():
    runner = RacingRunner(Bandit(nan_at_step=STEPS + 3), _cfg(), log_dir=None, device="cpu")
    runner.start()
    runner.iteration(7)
    with pytest.raises(NonFiniteEnvError, match=r"^iteration 8: The rewards .* NaN"):
        runner.iteration(8)


def test_nan_check_follows_the_config_switch():
    env = Bandit(nan_at_step=3)
    cfg = _cfg(check_for_nan=False)
    cfg["algorithm"].update(num_learning_epochs=1, num_mini_batches=1)  # one step on the NaN
    runner = RacingRunner(env, cfg, log_dir=None, device="cpu")
    runner.start()
    losses = runner.iteration(0)
    assert env.steps == STEPS and math.isnan(losses["value"])


class _ThreadsSeen(Bandit):
    """A bandit that records torch's thread count at every step (collection)."""

    def __init__(self) -> None:
        super().__init__()
        self.threads: set[int] = set()

    def step(self, actions):
        self.threads.add(torch.get_num_threads())
        return super().step(actions)


@pytest.mark.parametrize(("threads", "workers", "cores", "expected"), [
    (None, 0, 2, (2, 2)),  # in-process: every core in both phases
    (None, 2, 2, (1, 2)),  # two env workers: one learner thread beside them, both to update
    (None, 3, 16, (13, 16)),
    (None, 8, 4, (1, 4)),
    (1, 2, 16, (1, 1)),  # an explicit count is kept in both phases
])  # fmt: skip
def test_thread_counts_give_the_update_every_core_and_collection_what_workers_leave(
    threads: int | None, workers: int, cores: int, expected: tuple[int, int]
) -> None:
    assert thread_counts(threads, workers, cores) == expected


def test_the_runner_collects_and_updates_with_its_thread_counts(monkeypatch) -> None:
    before = torch.get_num_threads()
    env = _ThreadsSeen()
    monkeypatch.setattr("agents.runner.thread_counts", lambda threads, workers: (1, 2))
    updates: list[int] = []
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu", threads=None)
    real_update = runner.alg.update
    monkeypatch.setattr(
        runner.alg, "update", lambda: updates.append(torch.get_num_threads()) or real_update()
    )
    try:
        runner.learn(2)
    finally:
        torch.set_num_threads(before)
    assert env.threads == {1} and updates == [2, 2]
