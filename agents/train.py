"""Train a racing policy with rsl-rl's PPO and write a run in deepracer-for-cloud's layout.

Run layout (``RUN`` = the output folder)::

    RUN/training_settings.json                      how the run was started (for resume)
    RUN/ip/hyperparameters.json                     DeepRacer's hyperparameter keys
    RUN/model/model_metadata.json                   DeepRacer's model metadata
    RUN/model/model.zip                             the submission file (at the end)
    RUN/0/training-simtrace/<iteration>-iteration.csv
    RUN/evaluation-<YYYYMMDDHHMMSS>/evaluation-simtrace/0-iteration.csv
    RUN/metrics.csv, RUN/reward_graph.png           console-style metrics and graph
    RUN/checkpoints/last.pt                         state dicts (torch, weights_only)
    RUN/tensorboard/                                rsl-rl's TensorBoard events
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import time
from collections.abc import Callable
from copy import deepcopy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import torch
from pydantic import BaseModel, ConfigDict
from rsl_rl.runners import OnPolicyRunner

import arena
from agents import evaluate, export, networks, plots
from agents.hyperparameters import Hyperparameters
from agents.model_metadata import DeepRacerMetadata, write_model_metadata
from agents.selfplay import OpponentPool
from agents.vecenv import RacingVecEnv, resolve_reward
from arena.actions import ActionSpace, DiscreteActionSpace
from arena.config import RaceType
from arena.simtrace import write_simtrace
from tracks.catalog import get_track

METRICS_COLUMNS = (
    "iteration",
    "elapsed_s",
    "steps",
    "episodes",
    "mean_reward",
    "mean_progress",
    "lap_completion",
    "eval_progress",
    "eval_laps",
    "eval_best_lap",
    "eval_total_time",
    "eval_off_track",
    "value_loss",
    "surrogate_loss",
    "entropy",
)


class TrainSettings(BaseModel):
    """Everything that defines a training run (stored as ``RUN/training_settings.json``)."""

    model_config = ConfigDict(extra="forbid")

    track: str = "beginner_loop"
    race_type: RaceType = "time_trial"
    sensors: tuple[str, ...] = ("camera",)
    action_space: ActionSpace
    reward: str = "follow_center_line"
    network: str | None = None
    seed: int = 0
    workers: int | None = None
    races: int | None = None
    iterations: int | None = None
    minutes: float | None = None
    steps_per_env: int | None = None
    eval_every: int = 5
    eval_laps: int = 3
    eval_time_limit_s: float = 120.0
    stop_on_clean_eval: bool = False
    selfplay: Literal["shared", "pool"] = "shared"
    opponents: tuple[str, ...] = ()
    snapshot_every: int = 10
    device: str = "cpu"
    threads: int = 1

    @property
    def preset(self) -> str:
        """The network preset (default by sensors)."""
        return self.network or networks.default_preset(self.sensors)

    @property
    def discrete(self) -> bool:
        """Whether the action space is a discrete list."""
        return isinstance(self.action_space, DiscreteActionSpace)


@dataclass
class TrainResult:
    """How a run ended."""

    run_dir: Path
    iterations: int
    elapsed_s: float
    interrupted: bool = False
    first_clean_eval_s: float | None = None
    best_lap: float | None = None
    evaluations: list[dict[str, Any]] = field(default_factory=list)
    model_zip: Path | None = None


def _quiet() -> contextlib.AbstractContextManager:
    return contextlib.redirect_stdout(io.StringIO())


def _rank() -> int:
    return int(os.getenv("RANK", "0"))


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
        self.settings = settings
        self.run_dir = Path(run_dir)
        self.hp = hyperparameters or Hyperparameters()
        self.clone = Path(clone) if clone else None
        self.resume = resume
        networks.check_preset(settings.preset, settings.sensors)
        get_track(settings.track)  # raises TrackNotFoundError (a ValueError)
        resolve_reward(settings.reward, settings.race_type)  # fail early, in this process
        self.start_iteration = 0
        self.elapsed_before = 0.0

    # ------------------------------------------------------------------ setup
    def _write_run_files(self) -> None:
        s = self.settings
        self.run_dir.mkdir(parents=True, exist_ok=True)
        (self.run_dir / "training_settings.json").write_text(s.model_dump_json(indent=2))
        self.hp.write(self.run_dir)
        lidar = arena.CarConfig(name="car0").lidar_config
        meta = DeepRacerMetadata(
            action_space=s.action_space,
            sensors=s.sensors,
            neural_network=networks.deepracer_network_name(s.preset),
            lidar_config=lidar if any("sector" in x for x in s.sensors) else None,
        )
        (self.run_dir / "model").mkdir(exist_ok=True)
        write_model_metadata(self.run_dir / "model" / "model_metadata.json", meta)

    def _make_env(self) -> tuple[RacingVecEnv, OpponentPool | None]:
        s = self.settings
        config = arena.make_config(
            track=s.track,
            race_type=s.race_type,
            sensors=s.sensors,
            action_space=s.action_space,
            mode="training",
            seed=s.seed + 100_003 * _rank(),
        )
        pool = None
        learners = None
        if s.race_type == "head_to_model" and (s.selfplay == "pool" or s.opponents):
            pool = OpponentPool(seed=s.seed)
            for path in s.opponents:
                pool.add_policy(path)
            learners = [config.cars[0].name]
        env = RacingVecEnv(
            config,
            s.reward,
            num_races=s.races,
            num_workers=s.workers,
            learner_cars=learners,
            device=s.device,
        )
        return env, pool

    def _make_runner(self, env: RacingVecEnv) -> OnPolicyRunner:
        s = self.settings
        actor, critic, groups = networks.model_configs(s.preset, s.sensors, s.action_space)
        cfg = self.hp.to_rsl_rl(env.num_envs, actor, critic, groups, s.steps_per_env)
        log_dir = str(self.run_dir / "tensorboard") if _rank() == 0 else None
        with _quiet():
            runner = OnPolicyRunner(env, cfg, log_dir=log_dir, device=s.device)
        runner.logger.git_status_repos = []
        return runner

    def _load_weights(self, runner: OnPolicyRunner) -> None:
        if self.resume:
            ckpt = torch.load(self._checkpoint(), weights_only=True, map_location=runner.device)
            runner.alg.load(ckpt, None, strict=True)
            self.start_iteration = int(ckpt["iteration"]) + 1
            self.elapsed_before = float(ckpt["elapsed_s"])
        elif self.clone is not None:
            path = self.clone / "checkpoints" / "last.pt"
            ckpt = torch.load(path, weights_only=True, map_location=runner.device)
            try:
                runner.alg.load(ckpt, {"actor": True, "critic": True}, strict=True)
            except RuntimeError as exc:
                raise ValueError(
                    f"cannot clone {self.clone}: its network does not match this run's "
                    "(same sensors, network preset and number of actions are needed)"
                ) from exc

    def _checkpoint(self) -> Path:
        return self.run_dir / "checkpoints" / "last.pt"

    @staticmethod
    def _state(
        runner: OnPolicyRunner, iteration: int, elapsed: float, copy: bool = False
    ) -> dict[str, Any]:
        """The checkpoint content (state dicts; deep-copied when ``copy``)."""
        state = runner.alg.save()
        if copy:
            state = {k: deepcopy(v) for k, v in state.items()}
        return {**state, "iteration": iteration, "elapsed_s": elapsed}

    def _save(self, state: dict[str, Any]) -> None:
        if _rank() != 0:
            return
        path = self._checkpoint()
        path.parent.mkdir(parents=True, exist_ok=True)
        torch.save(state, path.with_suffix(".tmp"))
        path.with_suffix(".tmp").replace(path)

    # ------------------------------------------------------------------- loop
    def run(self, on_iteration: Callable[[dict[str, Any]], None] | None = None) -> TrainResult:
        """Train until the iteration or time budget is spent (or Ctrl-C); write outputs."""
        torch.set_num_threads(self.settings.threads)
        torch.manual_seed(self.settings.seed + _rank())
        if _rank() == 0:
            self._write_run_files()
        env, pool = self._make_env()
        result = TrainResult(self.run_dir, 0, 0.0)
        try:
            runner = self._make_runner(env)
            self._load_weights(runner)
            if pool is not None:
                pool.add_snapshot("snapshot:start", self._graph(runner))
            self._loop(runner, env, pool, result, on_iteration)
        finally:
            env.close()
        if _rank() == 0 and self._checkpoint().exists():
            result.model_zip = self._package(runner, result)
        return result

    def _loop(
        self,
        runner: OnPolicyRunner,
        env: RacingVecEnv,
        pool: OpponentPool | None,
        result: TrainResult,
        on_iteration: Callable[[dict[str, Any]], None] | None,
    ) -> None:
        """Iterate; on Ctrl-C keep the weights of the last finished iteration."""
        s = self.settings
        runner.alg.train_mode()
        runner.logger.init_logging_writer()
        self._obs = env.get_observations().to(runner.device)
        started = time.monotonic()
        it = self.start_iteration
        saved = it - 1
        before_update: dict[str, Any] | None = None
        try:
            while True:
                elapsed = self.elapsed_before + time.monotonic() - started
                if self._budget_spent(it, elapsed):
                    break
                if pool is not None:
                    env.set_opponents(dict(enumerate(pool.sample(env.num_races))))
                t0 = time.monotonic()
                self._rollout(runner, env)
                t1 = time.monotonic()
                before_update = self._state(runner, it - 1, elapsed, copy=True)
                losses = runner.alg.update()
                before_update = None
                self._log(runner, it, t1 - t0, time.monotonic() - t1, losses)
                elapsed = self.elapsed_before + time.monotonic() - started
                row = self._after_iteration(runner, env, pool, it, elapsed, losses, result)
                if row.get("eval_progress") != "":
                    self._save(self._state(runner, it, elapsed))
                    saved = it
                result.iterations, result.elapsed_s = it + 1 - self.start_iteration, elapsed
                it += 1
                if on_iteration is not None:
                    on_iteration(row)
                if s.stop_on_clean_eval and result.first_clean_eval_s is not None:
                    break
        except KeyboardInterrupt:
            result.interrupted = True
            if before_update is not None:
                self._save(before_update)
                return
        if saved != it - 1 and it > self.start_iteration:
            self._save(self._state(runner, it - 1, result.elapsed_s))

    def _rollout(self, runner: OnPolicyRunner, env: RacingVecEnv) -> None:
        """Collect one rollout (as rsl-rl's ``learn``) and compute the returns."""
        alg = runner.alg
        obs = self._obs
        with torch.inference_mode():
            for _ in range(runner.cfg["num_steps_per_env"]):
                actions = alg.act(obs)
                obs, rewards, dones, extras = env.step(actions.to(env.device))
                obs, rewards = obs.to(runner.device), rewards.to(runner.device)
                dones = dones.to(runner.device)
                alg.process_env_step(obs, rewards, dones, extras)
                runner.logger.process_env_step(rewards, dones, extras, None)
            alg.compute_returns(obs)
        self._obs = obs

    def _log(
        self,
        runner: OnPolicyRunner,
        it: int,
        collect_s: float,
        learn_s: float,
        losses: dict[str, float],
    ) -> None:
        """rsl-rl's TensorBoard logging (its console report is silenced)."""
        with _quiet():
            runner.logger.log(
                it=it,
                start_it=self.start_iteration,
                total_it=it + 1,
                collect_time=collect_s,
                learn_time=learn_s,
                loss_dict=losses,
                learning_rate=runner.alg.learning_rate,
                action_std=runner.alg.get_policy().output_std,
                rnd_weight=None,
            )

    def _budget_spent(self, it: int, elapsed: float) -> bool:
        s = self.settings
        done_its = it - self.start_iteration
        if s.iterations is not None and done_its >= s.iterations:
            return True
        return s.minutes is not None and elapsed - self.elapsed_before >= 60.0 * s.minutes

    def _last_iteration(self, it: int) -> bool:
        s = self.settings
        return s.iterations is not None and it + 1 - self.start_iteration >= s.iterations

    # -------------------------------------------------------------- outputs
    def _after_iteration(
        self,
        runner: OnPolicyRunner,
        env: RacingVecEnv,
        pool: OpponentPool | None,
        it: int,
        elapsed: float,
        losses: dict[str, float],
        result: TrainResult,
    ) -> dict[str, Any]:
        s = self.settings
        episodes = env.pop_episodes()
        rows = env.drain_simtrace()
        if pool is not None:
            for e in episodes:
                if "opponent" in e:
                    pool.record(e["opponent"], e["win"])
            if (it + 1) % s.snapshot_every == 0:
                pool.add_snapshot(f"snapshot:{it}", self._graph(runner))
        if _rank() == 0:
            path = self.run_dir / "0" / "training-simtrace" / f"{it}-iteration.csv"
            write_simtrace(path, rows)
        n = max(1, len(episodes))
        row: dict[str, Any] = {
            "iteration": it,
            "elapsed_s": round(elapsed, 2),
            "steps": len(rows),
            "episodes": len(episodes),
            "mean_reward": sum(e["reward"] for e in episodes) / n,
            "mean_progress": sum(e["progress"] for e in episodes) / n,
            "lap_completion": sum(e["lap_complete"] for e in episodes) / n,
            "value_loss": losses.get("value"),
            "surrogate_loss": losses.get("surrogate"),
            "entropy": losses.get("entropy"),
        }
        row.update(dict.fromkeys(c for c in METRICS_COLUMNS if c.startswith("eval_")))
        for key in row:
            if row[key] is None:
                row[key] = ""
        if _rank() == 0 and ((it + 1) % s.eval_every == 0 or self._last_iteration(it)):
            summary = self._evaluate(runner)
            result.evaluations.append({"iteration": it, "elapsed_s": elapsed, **summary})
            row.update(
                eval_progress=summary["progress"],
                eval_laps=summary["laps"],
                eval_best_lap=summary["best_lap"] if summary["best_lap"] is not None else "",
                eval_total_time=summary["total_time"] if summary["total_time"] else "",
                eval_off_track=summary["off_track"],
            )
            clean = summary["laps"] >= s.eval_laps and summary["off_track"] == 0
            if clean and result.first_clean_eval_s is None:
                result.first_clean_eval_s = elapsed
            if summary["best_lap"] is not None:
                result.best_lap = min(result.best_lap or 1e9, summary["best_lap"])
        if _rank() == 0:
            self._append_metrics(row)
            plots.reward_graph(self.run_dir / "metrics.csv", self.run_dir / "reward_graph.png")
        return row

    def _evaluate(self, runner: OnPolicyRunner) -> dict[str, Any]:
        s = self.settings
        config = evaluate.evaluation_config(
            s.track,
            s.race_type,
            s.sensors,
            s.action_space,
            laps=s.eval_laps,
            seed=s.seed,
            time_limit_s=s.eval_time_limit_s,
        )
        policy = evaluate.TorchPolicy(runner.alg.get_policy(), s.discrete)
        reward = resolve_reward(s.reward, s.race_type)
        race = evaluate.evaluate_policy(config, policy, reward_function=reward)
        runner.alg.train_mode()
        evaluate.write_evaluation(self.run_dir, race)
        return evaluate.summary(race)

    def _append_metrics(self, row: dict[str, Any]) -> None:
        path = self.run_dir / "metrics.csv"
        new = not path.exists()
        with path.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=METRICS_COLUMNS, extrasaction="ignore")
            if new:
                writer.writeheader()
            writer.writerow(row)

    def _graph(self, runner: OnPolicyRunner) -> bytes:
        s = self.settings
        return export.export_onnx(runner.alg.get_policy(), s.sensors, s.action_space)

    def _package(self, runner: OnPolicyRunner, result: TrainResult) -> Path | None:
        s = self.settings
        ckpt = torch.load(self._checkpoint(), weights_only=True, map_location="cpu")
        runner.alg.load(ckpt, {"actor": True}, strict=True)
        reward_source = Path(s.reward).read_text() if s.reward.endswith(".py") else None
        return export.pack_model(
            self.run_dir / "model" / "model.zip",
            self._graph(runner),
            s.action_space,
            s.sensors,
            neural_network=networks.deepracer_network_name(s.preset),
            network_preset=s.preset,
            lidar=None,
            training_summary={
                "track": s.track,
                "race_type": s.race_type,
                "iterations": int(ckpt["iteration"]) + 1,
                "minutes": round(float(ckpt["elapsed_s"]) / 60.0, 2),
                **({"best_lap": result.best_lap} if result.best_lap is not None else {}),
            },
            reward_source=reward_source,
            metrics_csv=self.run_dir / "metrics.csv",
        )


def load_settings(run_dir: str | Path) -> TrainSettings:
    """The settings a run was started with."""
    return TrainSettings.model_validate_json((Path(run_dir) / "training_settings.json").read_text())


def load_actor(run_dir: str | Path, device: str = "cpu") -> tuple[torch.nn.Module, TrainSettings]:
    """A run's trained actor (from ``checkpoints/last.pt``) and its settings."""
    settings = load_settings(run_dir)
    actor = networks.build_actor(settings.preset, settings.sensors, settings.action_space)
    ckpt = torch.load(
        Path(run_dir) / "checkpoints" / "last.pt", weights_only=True, map_location=device
    )
    actor.load_state_dict(ckpt["actor_state_dict"])
    return actor.to(device).eval(), settings
