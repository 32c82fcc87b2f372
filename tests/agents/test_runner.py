"""RacingRunner: rsl-rl's PPO one iteration at a time, in order or with the update
overlapping the next rollout, NaN check, no files of its own."""

from __future__ import annotations

import math
import time

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from agents.runner import NonFiniteEnvError, RacingRunner, thread_counts
from tests.agents.bandit import Bandit, ppo_config

MODES = pytest.mark.parametrize("sync", [True, False], ids=["sync", "overlapped"])

STEPS = 8


def _cfg(check_for_nan: bool = True) -> dict:
    return ppo_config("GaussianDistribution", steps=STEPS, check_for_nan=check_for_nan)


@MODES
def test_iterations_return_losses_and_log_only_tensorboard(tmp_path, capsys, sync: bool):
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=str(tmp_path), device="cpu", sync=sync)
    runner.start()
    losses = [runner.iteration(it) for it in (4, 5)]
    # overlapped, the first iteration collects one rollout more, to learn from meanwhile
    assert env.steps == (2 if sync else 3) * STEPS
    assert all(set(loss) == {"value", "surrogate", "entropy"} for loss in losses)
    assert runner.current_learning_iteration == 5
    runner.logger.writer.flush()
    files = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()}
    assert files and all(name.startswith("events.out.tfevents.") for name in files), files
    assert capsys.readouterr().out == ""
    tags = EventAccumulator(str(tmp_path)).Reload().Tags()["scalars"]
    assert "Loss/value" in tags
    assert ("Policy/behaviour_weight_spread" in tags) is not sync


@MODES
def test_learn_runs_that_many_iterations_from_start(sync: bool):
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu", sync=sync)
    runner.learn(3)
    assert env.steps == (3 if sync else 4) * STEPS
    assert runner.current_learning_iteration == 2


@MODES
def test_both_modes_learn_the_paying_arm(sync: bool):
    torch.manual_seed(0)
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu", sync=sync)
    runner.learn(30)
    obs = env.get_observations()
    with torch.no_grad():
        chosen = runner.alg.get_policy()(obs).argmax(dim=-1)
    assert (chosen == 2).all()


def test_overlapped_updates_learn_from_a_rollout_one_update_behind():
    torch.manual_seed(0)
    sync = RacingRunner(Bandit(), _cfg(), log_dir=None, device="cpu", sync=True)
    overlapped = RacingRunner(Bandit(), _cfg(), log_dir=None, device="cpu")
    assert overlapped.overlapped and not sync.overlapped
    for runner in (sync, overlapped):
        runner.learn(4)
    # the policy that starts an update differs from the one that collected its rollout
    assert sync.staleness == 0.0 and overlapped.staleness > 0.0
    t = overlapped.timings
    assert t.wall > 0 and 0 < t.collect <= t.wall and 0 < t.update <= t.wall


def test_a_failing_overlapped_update_stops_training_once_collection_ends(monkeypatch):
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu")
    runner.start()
    runner.iteration(0)

    def broken() -> dict[str, float]:
        raise RuntimeError("update broke")

    monkeypatch.setattr(runner.alg, "update", broken)
    steps = env.steps
    with pytest.raises(RuntimeError, match="update broke"):
        runner.iteration(1)
    assert env.steps == steps + STEPS  # the rollout beside it was collected whole


def test_an_interrupted_rollout_waits_for_the_update_beside_it(monkeypatch):
    env = Bandit()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu")
    runner.start()
    runner.iteration(0)
    finished: list[bool] = []
    real_update = runner.alg.update

    def slow_update() -> dict[str, float]:
        time.sleep(0.2)
        losses = real_update()
        finished.append(True)
        return losses

    def interrupted(actions):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner.alg, "update", slow_update)
    monkeypatch.setattr(env, "step", interrupted)
    with pytest.raises(KeyboardInterrupt):
        runner.iteration(1)
    assert finished == [True]  # no update is left changing the weights after Ctrl-C


def test_iteration_needs_start():
    runner = RacingRunner(Bandit(), _cfg(), log_dir=None, device="cpu")
    with pytest.raises(RuntimeError, match="start"):
        runner.iteration(0)


def test_nan_from_the_env_stops_training_naming_the_iteration():
    runner = RacingRunner(
        Bandit(nan_at_step=STEPS + 3), _cfg(), log_dir=None, device="cpu", sync=True
    )
    runner.start()
    runner.iteration(7)
    with pytest.raises(NonFiniteEnvError, match=r"^iteration 8: The rewards .* NaN"):
        runner.iteration(8)


def test_nan_check_follows_the_config_switch():
    env = Bandit(nan_at_step=3)
    cfg = _cfg(check_for_nan=False)
    cfg["algorithm"].update(num_learning_epochs=1, num_mini_batches=1)  # one step on the NaN
    runner = RacingRunner(env, cfg, log_dir=None, device="cpu", sync=True)
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


def _update_threads(runner: RacingRunner, monkeypatch) -> list[int]:
    """Train two iterations; torch's thread count at the start of each update."""
    before = torch.get_num_threads()
    updates: list[int] = []
    real_update = runner.alg.update
    monkeypatch.setattr(
        runner.alg, "update", lambda: updates.append(torch.get_num_threads()) or real_update()
    )
    try:
        runner.learn(2)
    finally:
        torch.set_num_threads(before)
    return updates


def test_the_runner_collects_and_updates_with_its_thread_counts(monkeypatch) -> None:
    env = _ThreadsSeen()
    monkeypatch.setattr("agents.runner.thread_counts", lambda threads, workers: (1, 2))
    # Every update counts as having had its cores, however busy the test machine is.
    monkeypatch.setattr("agents.learner_threads.SHARE_FLOOR", 0.0)
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu", threads=None, sync=True)
    assert _update_threads(runner, monkeypatch) == [2, 2] and env.threads == {1}


def test_an_update_starved_of_cpu_time_sends_the_next_ones_to_one_thread(monkeypatch) -> None:
    env = _ThreadsSeen()
    monkeypatch.setattr("agents.runner.thread_counts", lambda threads, workers: (2, 2))
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu", threads=None, sync=True)
    real_update = runner.alg.update
    # The update waits without running, as when other processes hold the cores.
    monkeypatch.setattr(runner.alg, "update", lambda: time.sleep(0.1) or real_update())
    assert _update_threads(runner, monkeypatch) == [2, 1] and env.threads == {2, 1}


def test_an_explicit_thread_count_is_kept_however_starved(monkeypatch) -> None:
    env = _ThreadsSeen()
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu", threads=2, sync=True)
    real_update = runner.alg.update
    monkeypatch.setattr(runner.alg, "update", lambda: time.sleep(0.1) or real_update())
    assert _update_threads(runner, monkeypatch) == [2, 2] and runner.learner_threads is None


def test_overlapped_collection_and_update_share_the_cores_the_workers_leave(monkeypatch):
    env = _ThreadsSeen()
    env.num_workers = 2
    monkeypatch.setattr("agents.runner.os.sched_getaffinity", lambda pid: set(range(6)))
    runner = RacingRunner(env, _cfg(), log_dir=None, device="cpu", threads=None)
    assert _update_threads(runner, monkeypatch) == [4, 4]
    assert runner.threads == (4, 4) and env.threads == {4}
