"""Train a racing policy with rsl-rl's PPO (or by imitation, ``agents.imitation``) into a
run folder in deepracer-for-cloud's layout (``agents.run``).
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from copy import deepcopy
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import torch

import arena
from agents import evaluate, export, networks, plots
from agents.anchor import anchored_config
from agents.background_eval import BackgroundEvaluator
from agents.checkpoint import checkpoint, checkpoint_path, read_checkpoint, write_checkpoint
from agents.deepracer_metrics import TrainingMetricsLog
from agents.evaluate import EvalSummary
from agents.hyperparameters import Hyperparameters
from agents.imitation import imitation_config
from agents.metrics import IterationStats, append_metrics
from agents.processes import STOP_SIGNALS
from agents.run import Run, holds_run
from agents.runner import RacingRunner
from agents.selfplay import OpponentPool, pursuit_lap_s
from agents.settings import TrainSettings
from agents.vecenv import RacingVecEnv
from arena.race import RaceResult
from arena.simtrace import write_simtrace
from tracks.catalog import get_track


@dataclass(frozen=True)
class _Evaluated:
    """An iteration's stats before its evaluation, and, if one is due, its checkpoint."""

    stats: IterationStats
    content: dict[str, Any] | None = None


@dataclass
class _LoopState:
    """Where the training loop stands: the last finished iteration (outputs written), the
    one in ``last.pt``, the last begun (its update maybe applied, in part if interrupted),
    and the state after the finished one while the weights may have moved past it."""

    finished: int
    finished_at: float
    saved: int = field(init=False)
    latest: int = field(init=False)
    fallback: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        self.saved = self.latest = self.finished

    def finish(self, iteration: int, elapsed_s: float, content: dict[str, Any] | None) -> None:
        """Iteration ``iteration`` is finished (``content``: its checkpoint, if taken)."""
        self.finished, self.finished_at, self.fallback = iteration, elapsed_s, content


@dataclass
class TrainResult:
    """How a run ended."""

    run_dir: Path
    iterations: int = 0  # iterations finished in this session
    elapsed_s: float = 0.0  # training time of the run, earlier sessions included
    interrupted: bool = False
    first_clean_eval_s: float | None = None
    evaluations: list[IterationStats] = field(default_factory=list)  # iterations that evaluated
    model_zip: Path | None = None

    @property
    def best_lap(self) -> float | None:
        """The best lap of this session's evaluations."""
        laps = [s.eval.best_lap for s in self.evaluations if s.eval and s.eval.best_lap is not None]
        return min(laps, default=None)


def _rank() -> int:
    return int(os.getenv("RANK", "0"))


# PPO updates that train only the critic at the start of a clone whose critic is new.
CLONE_CRITIC_WARMUP = 5
# In a pool self-play run's folder: each opponent's games, win rate, draw chance and pace.
POOL_FILE = "selfplay_pool.json"


@contextmanager
def _stop_signals_interrupt() -> Iterator[None]:
    """In the block, SIGTERM and SIGHUP raise KeyboardInterrupt as Ctrl-C does, so training
    stops the same way (checkpoint written, workers closed); restored afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, signal.default_int_handler) for sig in STOP_SIGNALS[1:]}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextmanager
def _sigint_deferred() -> Iterator[None]:
    """Hold a stop signal (Ctrl-C, SIGTERM, SIGHUP) that arrives in the block until the
    block has run."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {
        sig: signal.signal(sig, lambda signum, frame: caught.append(signum)) for sig in STOP_SIGNALS
    }
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if caught and callable(handler := previous[caught[0]]):
        handler(caught[0], None)  # Python's default SIGINT handler raises KeyboardInterrupt


class Trainer:
    """One training run: builds the env and runner, loops, evaluates, writes outputs."""

    def __init__(
        self,
        settings: TrainSettings,
        run_dir: str | Path,
        hyperparameters: Hyperparameters | None = None,
        clone: str | Path | None = None,
        resume: bool = False,
    ) -> None:
        run_dir = Path(run_dir)
        stored = Run.load(run_dir) if resume else None
        self.clone = Run.load(clone) if clone else None
        hp = hyperparameters or (stored.hyperparameters if stored else Hyperparameters())
        if self.clone is not None and "stack_size" not in hp.model_fields_set:
            # A clone's network reads as many frames as its parent's, unless told otherwise.
            hp = hp.model_copy(update={"stack_size": self.clone.stack_size})
        self.target = Run(run_dir, settings, hp)
        self.resume = resume
        if stored is None and holds_run(run_dir):
            raise ValueError(
                f"{run_dir} already holds a training run: continue it with --resume, "
                "or give another --out"
            )
        if stored is not None and stored.stack_size != hp.stack_size:
            raise ValueError(
                f"cannot resume {run_dir} with stack_size {hp.stack_size}: "
                f"its network reads {stored.stack_size} stacked frames"
            )
        self.dr_metrics = TrainingMetricsLog(run_dir, resume=resume)
        networks.check_preset(settings.preset, settings.sensors)
        for track in (settings.track, *settings.also_tracks):
            get_track(track)  # raises TrackNotFoundError (a ValueError)
        self.target.reward  # noqa: B018 (resolved here: a broken reward fails early)
        self.start_iteration = 0
        self.elapsed_before = 0.0
        self.writes_run_folder = _rank() == 0  # under torchrun, rank 0 alone
        self.eval_opponent = evaluate.run_opponent(settings) if self.writes_run_folder else None
        self.pursuit_lap_s: float | None = None  # measured once, for paced pool racers
        self.best_score = stored.best_score() if stored else None
        self.fastest_lap = stored.fastest_lap() if stored else None
        self.critic_warmup = self._critic_warmup()

    @property
    def settings(self) -> TrainSettings:
        """The settings the run trains with."""
        return self.target.settings

    @property
    def hp(self) -> Hyperparameters:
        """The run's DeepRacer hyperparameters."""
        return self.target.hyperparameters

    @property
    def run_dir(self) -> Path:
        """The run folder."""
        return self.target.path

    def _make_env(self) -> tuple[RacingVecEnv, OpponentPool | None]:
        s = self.settings
        config = arena.make_config(
            track=s.track,
            direction=s.direction,
            race_type=s.race_type,
            sensors=s.sensors,
            action_space=s.action_space,
            mode="training",
            seed=s.seed + 100_003 * _rank(),
            stack_size=self.target.stack_size,
            **s.race_rules(),
        )
        pool = None
        learners = None
        if s.race_type == "head_to_model" and (s.selfplay == "pool" or s.opponent):
            pool = OpponentPool(seed=s.seed)
            for path in s.opponent:
                pool.add_policy(path)
            for share in s.paced_rivals:
                pool.add_paced(share)
            learners = [config.cars[0].name]
        env = RacingVecEnv(
            config,
            s.reward_fn,
            num_races=s.races,
            num_workers=s.workers,
            learner_cars=learners,
            device=s.device,
            privileged=s.critic == "privileged" and s.teacher is None,
            expert=s.teacher is not None or s.anchor is not None,
            also_tracks=s.also_tracks,
        )
        return env, pool

    def _make_runner(self, env: RacingVecEnv) -> RacingRunner:
        s = self.settings
        actor, critic, groups = networks.model_configs(
            s.preset, s.sensors, s.action_space, s.critic
        )
        if s.min_std is not None:  # a Gaussian's (refused with a discrete space)
            actor["distribution_cfg"] = {**actor["distribution_cfg"], "std_range": (s.min_std, 1e6)}
        cfg = self.hp.to_rsl_rl(
            env.num_envs, actor, critic, groups, s.steps_per_env, grow=s.grows_batch
        )
        if s.teacher is not None:
            cfg = imitation_config(cfg, s.discrete, s.teacher_drives)
        if s.anchor is not None or self.critic_warmup:
            anchored = s.anchor is not None
            cfg = anchored_config(
                cfg,
                critic_warmup=self.critic_warmup,
                anchor_weight=s.anchor_weight if anchored else 0.0,
                anchor_updates=s.anchor_iterations if anchored else None,
                discrete=s.discrete,
            )
        log_dir = str(self.run_dir / "tensorboard") if self.writes_run_folder else None
        return RacingRunner(
            env, cfg, log_dir=log_dir, device=s.device, threads=s.threads, sync=not s.overlapped
        )

    def _reuses_clone_critic(self) -> bool:
        """Whether the clone's critic is loaded: it reads this run's inputs (an imitation
        run has none)."""
        clone = self.clone
        return clone is not None and (
            clone.settings.teacher is None and clone.settings.critic == self.settings.critic
        )

    def _critic_warmup(self) -> int:
        """PPO updates in which only the critic learns: the setting, else
        :data:`CLONE_CRITIC_WARMUP` for a clone whose critic is not reused."""
        s = self.settings
        if s.teacher is not None:
            return 0
        if s.critic_warmup is not None:
            return s.critic_warmup
        fresh = self.clone is not None and not self.resume and not self._reuses_clone_critic()
        return CLONE_CRITIC_WARMUP if fresh else 0

    def _load_weights(self, runner: RacingRunner) -> None:
        if self.resume:
            ckpt = read_checkpoint(self.run_dir, runner.device)
            runner.alg.load(ckpt, None, strict=True)
            self.start_iteration = int(ckpt["iteration"]) + 1
            self.elapsed_before = float(ckpt["elapsed_s"])
        elif self.clone is not None:
            ckpt = self.clone.checkpoint(runner.device)
            # A critic that reads other inputs than this run's cannot be reused: a fresh one
            # (an imitation run has none).
            same_critic = self._reuses_clone_critic() and "critic_state_dict" in ckpt
            try:
                runner.alg.load(ckpt, {"actor": True, "critic": same_critic}, strict=True)
            except RuntimeError as exc:
                raise ValueError(
                    f"cannot clone {self.clone.path}: its network does not match this run's "
                    "(same sensors, network preset, number of actions and stack_size are "
                    "needed)"
                ) from exc

    @staticmethod
    def _checkpoint(
        runner: RacingRunner, iteration: int, elapsed_s: float, copy: bool = False
    ) -> dict[str, Any]:
        """The checkpoint content now (deep-copied when ``copy``: kept past an update)."""
        state = runner.alg.save()
        if copy:
            state = {k: deepcopy(v) for k, v in state.items()}
        return checkpoint(state, iteration, elapsed_s)

    def _save(self, content: dict[str, Any]) -> None:
        if self.writes_run_folder:
            write_checkpoint(self.run_dir, content)

    def _save_if_best(self, content: dict[str, Any], evaluation: EvalSummary) -> None:
        """Keep ``content`` as ``best.pt`` when ``evaluation`` beats the run's best, and as
        ``fastest.pt`` when its best lap beats the run's fastest.

        Evaluations within the critic warm-up race the clone's actor unchanged, not this
        run's: they compete for neither (a run packing them would pack its parent)."""
        if int(content["iteration"]) < self.critic_warmup:
            return
        kept = {"eval_score": list(evaluation.score), "eval_best_lap": evaluation.best_lap}
        if self.best_score is None or evaluation.score > self.best_score:
            self.best_score = evaluation.score
            write_checkpoint(self.run_dir, {**content, **kept}, "best")
        lap = evaluation.best_lap
        if lap is not None and (self.fastest_lap is None or lap < self.fastest_lap):
            self.fastest_lap = lap
            write_checkpoint(self.run_dir, {**content, **kept}, "fastest")

    # ------------------------------------------------------------------- loop
    def run(self, on_iteration: Callable[[IterationStats], None] | None = None) -> TrainResult:
        """Train until the iteration or time budget is spent (or Ctrl-C, SIGTERM, SIGHUP);
        write outputs.

        ``on_iteration`` receives each finished iteration's statistics.
        """
        torch.manual_seed(self.settings.seed + _rank())
        if self.writes_run_folder:
            self.target.write()
        with _stop_signals_interrupt():
            env, pool = self._make_env()
            result = TrainResult(self.run_dir)
            try:
                runner = self._make_runner(env)
                self._load_weights(runner)
                if pool is not None:
                    pool.add_snapshot("snapshot:start", self._graph(runner))
                self._loop(runner, env, pool, result, on_iteration)
            finally:
                env.close()
        if self.writes_run_folder and checkpoint_path(self.run_dir).exists():
            result.model_zip = self._package()
        return result

    def _loop(
        self,
        runner: RacingRunner,
        env: RacingVecEnv,
        pool: OpponentPool | None,
        result: TrainResult,
        on_iteration: Callable[[IterationStats], None] | None,
    ) -> None:
        """Iterate; checkpoint at each evaluation and at the end.

        An iteration is finished once its outputs are written. With ``--background-eval``
        an evaluation races in a process of its own while the next iteration trains, and
        the evaluated iteration is finished after that next one's update. On Ctrl-C the
        checkpoint holds the last finished iteration, never a half-applied update.
        """
        runner.start()
        started = time.monotonic() - self.elapsed_before

        def elapsed() -> float:
            return time.monotonic() - started

        loop = _LoopState(self.start_iteration - 1, self.elapsed_before)
        background = self.settings.background_eval and self.writes_run_folder
        evaluator: BackgroundEvaluator | None = None  # started at the first evaluation
        pending: _Evaluated | None = None  # an iteration whose evaluation races elsewhere

        def finish(done: _Evaluated, evaluation: EvalSummary | None) -> None:
            stats = self._conclude(done, evaluation, pool)
            with _sigint_deferred():  # the iteration's outputs are written whole
                self._write_outputs(stats)
                if stats.eval is not None and done.content is not None:
                    self._save(done.content)
                    self._save_if_best(done.content, stats.eval)
                    loop.saved = stats.iteration
                loop.finish(stats.iteration, stats.elapsed_s, done.content)
            self._record(result, stats)
            if on_iteration is not None:
                on_iteration(stats)

        try:
            spent = self._budget_spent(loop.latest + 1, elapsed())
            while not spent:
                it = loop.latest + 1
                self._draw_opponents(env, pool)
                if loop.latest == loop.finished:
                    state = self._checkpoint(runner, loop.finished, loop.finished_at, copy=True)
                    loop.fallback = state
                loop.latest = it
                losses = runner.iteration(it)
                stats = self._finish_iteration(runner, env, pool, it, elapsed(), losses)
                # One reading of the clock says both that this iteration is the last and
                # that it is evaluated as the last (a later reading could stop unevaluated).
                spent = self._last_iteration(it, stats.elapsed_s)
                if pending is not None and evaluator is not None:
                    finish(pending, self._summarize(evaluator.result()))
                    pending = None
                if not self._evaluation_due(it, spent):
                    finish(_Evaluated(stats), None)
                elif not background:
                    evaluation = self._evaluate(runner)
                    content = self._checkpoint(runner, it, stats.elapsed_s)
                    finish(_Evaluated(stats, content), evaluation)
                else:
                    content = self._checkpoint(runner, it, stats.elapsed_s, copy=True)
                    evaluator = evaluator or BackgroundEvaluator(self.target)
                    evaluator.submit(runner.alg.get_policy())
                    pending = _Evaluated(stats, content)
                if self.settings.stop_on_clean_eval and result.first_clean_eval_s is not None:
                    break
            if pending is not None and evaluator is not None:
                finish(pending, self._summarize(evaluator.result()))
        except KeyboardInterrupt:
            result.interrupted = True
        finally:
            if evaluator is not None:
                evaluator.close()
        if loop.saved != loop.finished:  # the state after the last finished iteration
            if loop.latest == loop.finished:
                self._save(self._checkpoint(runner, loop.finished, loop.finished_at))
            elif loop.fallback is not None:
                self._save(loop.fallback)

    def _budget_spent(self, it: int, elapsed: float) -> bool:
        s = self.settings
        done_its = it - self.start_iteration
        if s.iterations is not None and done_its >= s.iterations:
            return True
        return s.minutes is not None and elapsed - self.elapsed_before >= 60.0 * s.minutes

    def _last_iteration(self, it: int, elapsed: float) -> bool:
        """Whether iteration ``it``, finished at ``elapsed`` seconds, spends the budget."""
        return self._budget_spent(it + 1, elapsed)

    # ------------------------------------------------------ between iterations
    @staticmethod
    def _draw_opponents(env: RacingVecEnv, pool: OpponentPool | None) -> None:
        """Give every race an opponent from the pool for the next rollout."""
        if pool is not None:
            env.set_opponents(dict(enumerate(pool.sample(env.num_races))))

    def _finish_iteration(
        self,
        runner: RacingRunner,
        env: RacingVecEnv,
        pool: OpponentPool | None,
        it: int,
        elapsed: float,
        losses: dict[str, float],
    ) -> IterationStats:
        """After an update: the pool learns the results, simtrace; the stats (no evaluation
        yet: :meth:`_conclude` adds it)."""
        episodes = env.pop_episodes()
        simtrace = env.drain_simtrace()
        if pool is not None:
            self._update_pool(pool, runner, it, episodes)
        if self.writes_run_folder:
            self._write_training_simtrace(it, simtrace)
            self.dr_metrics.add_training(episodes)
        return IterationStats.of_iteration(it, elapsed, len(simtrace), episodes, losses, None)

    def _conclude(
        self, done: _Evaluated, evaluation: EvalSummary | None, pool: OpponentPool | None
    ) -> IterationStats:
        """An iteration's stats with its ``evaluation``, if it had one, which paces the
        pool's paced racers."""
        if evaluation is None:
            return done.stats
        if pool is not None:
            self._pace_pool(pool, evaluation)
        return replace(done.stats, eval=evaluation)

    def _write_outputs(self, stats: IterationStats) -> None:
        """``TrainingMetrics.json``, then the iteration's ``metrics.csv`` row and graph."""
        if self.writes_run_folder:
            self.dr_metrics.write()
            self._write_metrics(stats)

    def _write_training_simtrace(self, it: int, rows: list[dict[str, Any]]) -> None:
        write_simtrace(self.run_dir / "0" / "training-simtrace" / f"{it}-iteration.csv", rows)

    def _write_metrics(self, stats: IterationStats) -> None:
        """Append the iteration to ``metrics.csv`` and redraw the reward graph."""
        append_metrics(self.run_dir / "metrics.csv", stats)
        plots.reward_graph(self.run_dir / "metrics.csv", self.run_dir / "reward_graph.png")

    def _update_pool(
        self,
        pool: OpponentPool,
        runner: RacingRunner,
        it: int,
        episodes: list[dict[str, Any]],
    ) -> None:
        """Record the learner's wins and losses; snapshot it every ``snapshot_every``;
        write the pool's table (``POOL_FILE``)."""
        for e in episodes:
            if "opponent" in e:
                pool.record(e["opponent"], e["win"])
        if (it + 1) % self.settings.snapshot_every == 0:
            pool.add_snapshot(f"snapshot:{it}", self._graph(runner))
        if self.writes_run_folder:
            table = {"iteration": it, "opponents": pool.table()}
            (self.run_dir / POOL_FILE).write_text(json.dumps(table, indent=1) + "\n")

    def _pace_pool(self, pool: OpponentPool, evaluation: EvalSummary) -> None:
        """Pace the pool's paced racers to the learner's laps in ``evaluation``
        (:attr:`EvalSummary.pace_lap`); nothing if it finished no lap."""
        lap = evaluation.pace_lap
        if lap is None or not self.settings.paced_rivals:
            return
        if self.pursuit_lap_s is None:
            trial = self.target.evaluation_config(race_type="time_trial")
            self.pursuit_lap_s = pursuit_lap_s(trial)
        if self.pursuit_lap_s is not None:
            pool.set_pace(lap, self.pursuit_lap_s)

    def _evaluation_due(self, it: int, last: bool) -> bool:
        """Every ``eval_every`` iterations and after the ``last`` one, which spends the
        budget of iterations or of minutes (rank 0 only)."""
        every = (it + 1) % self.settings.eval_every == 0
        return self.writes_run_folder and (every or last)

    def _evaluate(self, runner: RacingRunner) -> EvalSummary:
        """Race the greedy policy in this process in the run's evaluation races (race
        mode; head to model: against the run's first ``--opponent``); write the first
        race's simtrace."""
        policy = evaluate.TorchPolicy(runner.alg.get_policy(), self.settings.discrete)
        races = [
            evaluate.evaluate_policy(
                config, policy, reward_function=self.target.reward, opponent=self.eval_opponent
            )
            for config in self.target.evaluation_configs()
        ]
        runner.alg.train_mode()
        return self._summarize(races)

    def _summarize(self, races: list[RaceResult]) -> EvalSummary:
        """Write the simtrace and laps of an evaluation's first race (on ``--track``); the
        headline numbers of all its races."""
        evaluate.write_evaluation(self.run_dir, races[0], training_log=self.dr_metrics)
        return evaluate.evaluation_summary(races)

    def _record(self, result: TrainResult, stats: IterationStats) -> None:
        """Count the iteration in ``result``, with its evaluation if it had one."""
        result.iterations = stats.iteration + 1 - self.start_iteration
        result.elapsed_s = stats.elapsed_s
        if stats.eval is None:
            return
        result.evaluations.append(stats)
        if stats.eval.clean(self.settings.eval_laps) and result.first_clean_eval_s is None:
            result.first_clean_eval_s = stats.elapsed_s

    # -------------------------------------------------------------- outputs
    def _graph(self, runner: RacingRunner) -> bytes:
        s = self.settings
        policy = runner.alg.get_policy()
        return export.export_onnx(
            policy, s.sensors, s.action_space, stack_size=self.target.stack_size
        )

    def _package(self) -> Path:
        return self.target.pack(self.target.model_zip)
