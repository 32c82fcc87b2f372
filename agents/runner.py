"""rsl-rl's on-policy runner, stepped one iteration at a time (written against rsl-rl-lib 5.5.1).

``OnPolicyRunner.learn`` runs a fixed number of iterations with nothing between them but
its own checkpoint files. A training run here stops on a wall-clock budget or Ctrl-C, and
between iterations it evaluates, checkpoints and swaps self-play opponents
(``agents.train``). So :class:`RacingRunner` splits ``learn`` into :meth:`~RacingRunner.start`
and :meth:`~RacingRunner.iteration`, which call rsl-rl's own pieces (the algorithm's
``act``/``process_env_step``/``compute_returns``/``update``, the logger, ``check_nan``) in
``learn``'s order. Those pieces are rsl-rl internals: ``pyproject.toml`` pins rsl-rl-lib
to 5.5.x for them.

A PPO runner may overlap the two halves of an iteration (``sync=False``): the learner
updates on the last rollout in a thread while the env workers collect the next one with a
copy of the policy taken before that update (:class:`Behaviour`). That rollout is
therefore one update behind the policy that learns from it, which the update corrects as
decoupled PPO does (:meth:`RacingRunner._rebase_on_proximal`); :attr:`RacingRunner.staleness`
is the mean ``|pi_prox / mu - 1|`` it corrected. benchmarks/RESULTS.md, "Overlapped
collection", gives figures.
"""

from __future__ import annotations

import contextlib
import copy
import io
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils import check_nan
from tensordict import TensorDict

from agents.learner_threads import LearnerThreads
from agents.networks import channels_last, images_pooled_once

# Largest weight of a sample's advantage, pi_prox / mu, in an overlapped update: a bound
# on the variance one rare action of the collecting policy can add.
MAX_BEHAVIOUR_WEIGHT = 2.0


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


@dataclass(frozen=True)
class IterationTimings:
    """Seconds of one iteration: its wall time, collecting and updating (which overlap
    unless the runner is synchronous); the torch threads the update ran on."""

    wall: float = 0.0
    collect: float = 0.0
    update: float = 0.0
    update_threads: int = 0


class Behaviour:
    """The algorithm as the rollout collector sees it: rsl-rl's own ``act``,
    ``process_env_step`` and ``compute_returns`` on a copy of the actor and critic, with
    its own transition and storage, so the learner can update the originals meanwhile.

    Everything else (gamma, lambda, the return scale's running statistics, which only
    collection changes) is the algorithm's own.
    """

    def __init__(self, alg: object) -> None:
        self.alg = copy.copy(alg)
        self.alg.actor = copy.deepcopy(alg.actor)
        self.alg.critic = copy.deepcopy(alg.critic)
        self.alg.storage = copy.deepcopy(alg.storage)
        self.alg.transition = type(alg.transition)()
        for model in (self.alg.actor, self.alg.critic):
            model.requires_grad_(False)

    def sync(self, alg: object) -> None:
        """Take the learner's current weights (and observation normalisers)."""
        with torch.no_grad():
            self.alg.actor.load_state_dict(alg.actor.state_dict())
            self.alg.critic.load_state_dict(alg.critic.state_dict())

    def swap_storage(self, alg: object) -> None:
        """Hand the collected rollout to the learner and take its emptied storage."""
        alg.storage, self.alg.storage = self.alg.storage, alg.storage


class _Background:
    """``fn()`` run in a thread; :meth:`result` joins it and re-raises what it raised."""

    def __init__(self, fn: Callable[[], Any]) -> None:
        self._result: Any = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(fn,), name="ppo-update")
        self._thread.start()

    def _run(self, fn: Callable[[], Any]) -> None:
        try:
            self._result = fn()
        except BaseException as exc:  # re-raised in the caller's thread
            self._error = exc

    def result(self) -> Any:
        """``fn``'s return value, once the thread has ended."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._result


class RacingRunner(OnPolicyRunner):
    """An ``OnPolicyRunner`` driven by its caller: :meth:`start`, then :meth:`iteration` each time.

    Writes no checkpoint files (``agents.train`` does) and prints nothing; TensorBoard
    events go to ``log_dir`` as with rsl-rl's runner. ``threads``: torch CPU threads, as
    :func:`thread_counts` reads it (``None``: auto, which in turn on a CPU drops to one
    while other processes crowd the cores, :mod:`agents.learner_threads`). ``sync``:
    collect, then update, as rsl-rl does; otherwise (PPO only) the update overlaps the next
    rollout (module docstring).
    """

    def __init__(
        self,
        env: VecEnv,
        train_cfg: dict,
        log_dir: str | None,
        device: str,
        threads: int | None = None,
        sync: bool = False,
    ) -> None:
        with _quiet():
            super().__init__(env, train_cfg, log_dir=log_dir, device=device)
        # rsl-rl writes the git diff of the repositories listed here (by default its own)
        # into log_dir/git; installed in a checkout's virtualenv that would be the
        # project's diff, which has no place in a run folder.
        self.logger.git_status_repos.clear()
        if not self.device.startswith("cuda"):  # measured on CPUs only
            channels_last([m for m in vars(self.alg).values() if isinstance(m, torch.nn.Module)])
        self._obs: TensorDict | None = None
        self.timings = IterationTimings()  # the last iteration's
        self.staleness = 0.0  # the mean |w - 1| the last overlapped update corrected
        workers = getattr(env, "num_workers", 0)
        self.overlapped = not sync and hasattr(self.alg, "critic")  # imitation runs in order
        if self.overlapped:
            # Collection and update run at once: both get the cores the workers leave free.
            free = thread_counts(threads, max(1, workers))[0]
            self.threads = (free, free)
            self._behaviour = Behaviour(self.alg)
        else:
            self.threads = thread_counts(threads, workers)
        # Auto threads step down to one while other processes crowd the cores: in turn on a
        # CPU only (overlapped, the process's CPU time mixes collection into the update's;
        # on a GPU the update waits for the device, not for cores).
        adaptive = threads is None and not self.overlapped and not self.device.startswith("cuda")
        self.learner_threads = LearnerThreads(self.threads[1]) if adaptive else None
        self._pending = False  # the learner's storage holds a rollout not yet learned from

    def start(self) -> None:
        """What ``learn`` does before its first iteration: observations, train mode, synced
        parameters (multi-GPU) and the TensorBoard writer."""
        self._obs = self.env.get_observations().to(self.device)
        self.alg.train_mode()
        if self.is_distributed:
            self.alg.broadcast_parameters()
        self.logger.init_logging_writer()
        self._pending = False

    def iteration(self, it: int) -> dict[str, float]:
        """One PPO iteration (a rollout and an update, TensorBoard scalars); its mean losses.

        Overlapped, the update learns from the rollout collected during the iteration
        before (the first iteration collects one more to start), and the rollout collected
        now waits for the next iteration. Raises :class:`NonFiniteEnvError`, naming ``it``,
        when the config's ``check_for_nan`` is on and the environment returns NaN.
        """
        if self._obs is None:
            raise RuntimeError("call start() before iteration()")
        losses = self._overlapped_iteration(it) if self.overlapped else self._sync_iteration(it)
        self.current_learning_iteration = it
        self._log(it, self.timings.collect, self.timings.update, losses)
        return losses

    def learn(self, num_learning_iterations: int) -> None:
        """rsl-rl's entry point: :meth:`start`, then that many iterations from the current one."""
        self.start()
        first = self.current_learning_iteration
        for it in range(first, first + num_learning_iterations):
            self.iteration(it)

    def _sync_iteration(self, it: int) -> dict[str, float]:
        """Collect with the current policy, then update on that rollout."""
        started = time.monotonic()
        learner = self.learner_threads
        update_threads = self.threads[1] if learner is None else learner.now
        torch.set_num_threads(min(self.threads[0], update_threads))
        self._collect_rollout(it, self.alg)
        collected = time.monotonic()
        torch.set_num_threads(update_threads)
        cpu = time.process_time()
        losses = self._update()
        done = time.monotonic()
        if learner is not None:
            learner.measured(done - collected, time.process_time() - cpu)
        self.timings = IterationTimings(
            done - started, collected - started, done - collected, update_threads
        )
        return losses

    def _overlapped_iteration(self, it: int) -> dict[str, float]:
        """Update on the pending rollout in a thread while the next one is collected."""
        torch.set_num_threads(self.threads[0])
        if not self._pending:  # the pipeline's first rollout: nothing to overlap it with
            self._behaviour.sync(self.alg)
            self._collect_behind(it)
            self._behaviour.swap_storage(self.alg)
        started = time.monotonic()
        self._behaviour.sync(self.alg)
        update = _Background(self._timed_update)
        try:
            self._collect_behind(it)
            collected = time.monotonic()
        finally:
            losses, update_s = update.result()  # also on Ctrl-C: no update left running
        self._behaviour.swap_storage(self.alg)
        self._pending = True
        done = time.monotonic()
        self.timings = IterationTimings(
            done - started, collected - started, update_s, self.threads[1]
        )
        return losses

    def _collect_behind(self, it: int) -> None:
        """A rollout with the behaviour policy, whole on the device before the learner reads it."""
        self._collect_rollout(it, self._behaviour.alg)
        if self.device.startswith("cuda"):
            torch.cuda.current_stream().synchronize()

    def _timed_update(self) -> tuple[dict[str, float], float]:
        """The update (in the update thread): its losses and seconds; :attr:`staleness` first."""
        started = time.monotonic()
        stream = torch.cuda.Stream() if self.device.startswith("cuda") else None
        with torch.cuda.stream(stream) if stream else contextlib.nullcontext():
            losses = self._update(rebase=True)
        if stream is not None:
            stream.synchronize()
        return losses, time.monotonic() - started

    def _update(self, rebase: bool = False) -> dict[str, float]:
        """The algorithm's update, the rollout's images pooled once for it
        (:func:`~agents.networks.images_pooled_once`); ``rebase``: corrected first for a
        rollout one update behind (:attr:`staleness`)."""
        models = [
            getattr(self.alg, name) for name in ("actor", "critic") if hasattr(self.alg, name)
        ]
        with images_pooled_once(models, self.alg.storage.observations):
            if rebase:
                self.staleness = self._rebase_on_proximal()
            return self.alg.update()

    def _rebase_on_proximal(self) -> float:
        """Decoupled PPO's correction for a rollout one update behind; the mean ``|w - 1|``.

        ``w = pi_prox(a|s) / mu(a|s)``, the policy starting this update over the one that
        collected the rollout. The stored log-probabilities become the proximal policy's,
        so PPO clips around the policy it starts from (as when synchronous), and each
        advantage is weighted by ``w`` (at most :data:`MAX_BEHAVIOUR_WEIGHT`), so the
        objective stays an estimate under the collecting policy (Hilton et al., 2021,
        "Batch size-invariance for policy optimization").
        """
        st = self.alg.storage
        obs, actions = st.observations.flatten(0, 1), st.actions.flatten(0, 1)
        chunk = 4096
        with torch.no_grad():
            parts = []
            for i in range(0, actions.shape[0], chunk):
                self.alg.actor(obs[i : i + chunk], stochastic_output=True)
                parts.append(self.alg.actor.get_output_log_prob(actions[i : i + chunk]))
            proximal = torch.cat(parts).view_as(st.actions_log_prob)
            weight = torch.exp(proximal - st.actions_log_prob).clamp(max=MAX_BEHAVIOUR_WEIGHT)
            st.advantages = st.advantages * weight
            st.actions_log_prob.copy_(proximal)
        return float((weight - 1.0).abs().mean())

    def _collect_rollout(self, it: int, alg: object) -> None:
        """``num_steps_per_env`` steps of every slot with ``alg``'s policy into its
        storage, then the returns."""
        obs = self._obs
        with torch.inference_mode():
            for _ in range(self.cfg["num_steps_per_env"]):
                actions = alg.act(obs)
                obs, rewards, dones, extras = self.env.step(actions.to(self.env.device))
                if self.cfg.get("check_for_nan", True):
                    self._check_nan(it, obs, rewards, dones)
                obs = obs.to(self.device)
                rewards, dones = rewards.to(self.device), dones.to(self.device)
                alg.process_env_step(obs, rewards, dones, extras)
                self.logger.process_env_step(rewards, dones, extras, None)  # no RND
            alg.compute_returns(obs)
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
        writer = getattr(self.logger, "writer", None)
        if self.overlapped and writer is not None:
            writer.add_scalar("Policy/behaviour_weight_spread", self.staleness, it)
        if self.learner_threads is not None and writer is not None:
            writer.add_scalar("Perf/update_threads", self.timings.update_threads, it)
