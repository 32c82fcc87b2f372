"""rsl-rl's on-policy runner, stepped one iteration at a time (written against rsl-rl-lib 5.5.1).

``OnPolicyRunner.learn`` runs a fixed number of iterations with nothing between them but
its own checkpoint files. A training run here stops on a wall-clock budget or Ctrl-C, and
between iterations it evaluates, checkpoints and swaps self-play opponents
(``agents.train``). So :class:`RacingRunner` splits ``learn`` into :meth:`~RacingRunner.start`
and :meth:`~RacingRunner.iteration`, which call rsl-rl's own pieces (the algorithm's
``act``/``process_env_step``/``compute_returns``/``update``, the logger, ``check_nan``) in
``learn``'s order. Those pieces are rsl-rl internals: ``pyproject.toml`` pins rsl-rl-lib
to 5.5.x for them.
"""

from __future__ import annotations

import contextlib
import io
import os
import time

import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils import check_nan
from tensordict import TensorDict


class NonFiniteEnvError(ValueError):
    """The environment returned NaN during a rollout (checked when ``check_for_nan``)."""


def _quiet() -> contextlib.AbstractContextManager:
    """Swallow rsl-rl's console reports (the CLI shows its own progress)."""
    return contextlib.redirect_stdout(io.StringIO())


def thread_counts(threads: int | None, workers: int, cores: int | None = None) -> tuple[int, int]:
    """Torch CPU threads ``(while collecting, while updating)``.

    ``threads`` given: that many in both. ``None`` (auto): the update gets every core this
    process may use (the env workers wait for it), collection the cores the env workers
    leave free, at least one (the learner's threads then do not fight the workers; on 2
    cores with 2 workers, two learner threads cut lidar collection by a third,
    benchmarks/RESULTS.md, "Torch threads").
    """
    if threads is not None:
        return threads, threads
    cores = cores or len(os.sched_getaffinity(0))
    return max(1, cores - workers), cores


class RacingRunner(OnPolicyRunner):
    """An ``OnPolicyRunner`` driven by its caller: :meth:`start`, then :meth:`iteration` each time.

    Writes no checkpoint files (``agents.train`` does) and prints nothing; TensorBoard
    events go to ``log_dir`` as with rsl-rl's runner. ``threads``: torch CPU threads, as
    :func:`thread_counts` reads it (``None``: auto).
    """

    def __init__(
        self,
        env: VecEnv,
        train_cfg: dict,
        log_dir: str | None,
        device: str,
        threads: int | None = None,
    ) -> None:
        with _quiet():
            super().__init__(env, train_cfg, log_dir=log_dir, device=device)
        # rsl-rl writes the git diff of the repositories listed here (by default its own)
        # into log_dir/git; installed in a checkout's virtualenv that would be the
        # project's diff, which has no place in a run folder.
        self.logger.git_status_repos.clear()
        self._obs: TensorDict | None = None
        self.timings = (0.0, 0.0)  # the last iteration's (collection, update) seconds
        self.threads = thread_counts(threads, getattr(env, "num_workers", 0))

    def start(self) -> None:
        """What ``learn`` does before its first iteration: observations, train mode, synced
        parameters (multi-GPU) and the TensorBoard writer."""
        self._obs = self.env.get_observations().to(self.device)
        self.alg.train_mode()
        if self.is_distributed:
            self.alg.broadcast_parameters()
        self.logger.init_logging_writer()

    def iteration(self, it: int) -> dict[str, float]:
        """One PPO iteration (rollout, update, TensorBoard scalars); its mean losses.

        Raises :class:`NonFiniteEnvError`, naming ``it``, when the config's
        ``check_for_nan`` is on and the environment returns NaN.
        """
        if self._obs is None:
            raise RuntimeError("call start() before iteration()")
        started = time.monotonic()
        torch.set_num_threads(self.threads[0])
        self._collect_rollout(it)
        collected = time.monotonic()
        torch.set_num_threads(self.threads[1])
        losses = self.alg.update()
        self.current_learning_iteration = it
        self.timings = (collected - started, time.monotonic() - collected)
        self._log(it, *self.timings, losses)
        return losses

    def learn(self, num_learning_iterations: int) -> None:
        """rsl-rl's entry point: :meth:`start`, then that many iterations from the current one."""
        self.start()
        first = self.current_learning_iteration
        for it in range(first, first + num_learning_iterations):
            self.iteration(it)

    def _collect_rollout(self, it: int) -> None:
        """``num_steps_per_env`` steps of every slot, then the returns."""
        obs = self._obs
        with torch.inference_mode():
            for _ in range(self.cfg["num_steps_per_env"]):
                actions = self.alg.act(obs)
                obs, rewards, dones, extras = self.env.step(actions.to(self.env.device))
                if self.cfg.get("check_for_nan", True):
                    self._check_nan(it, obs, rewards, dones)
                obs = obs.to(self.device)
                rewards, dones = rewards.to(self.device), dones.to(self.device)
                self.alg.process_env_step(obs, rewards, dones, extras)
                self.logger.process_env_step(rewards, dones, extras, None)  # no RND
            self.alg.compute_returns(obs)
        self._obs = obs

    @staticmethod
    def _check_nan(it: int, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor) -> None:
        """rsl-rl's ``check_nan``, its message prefixed with the iteration."""
        try:
            check_nan(obs, rewards, dones)
        except ValueError as exc:
            raise NonFiniteEnvError(f"iteration {it}: {exc}") from exc

    def _log(self, it: int, collect_s: float, learn_s: float, losses: dict[str, float]) -> None:
        """rsl-rl's TensorBoard scalars for iteration ``it``."""
        with _quiet():
            self.logger.log(
                it=it,
                start_it=it,  # start_it and total_it only feed the silenced console ETA
                total_it=it + 1,
                collect_time=collect_s,
                learn_time=learn_s,
                loss_dict=losses,
                learning_rate=self.alg.learning_rate,
                action_std=self.alg.get_policy().output_std,
                rnd_weight=None,
            )
