"""A training run's folder as one object: its settings, hyperparameters, checkpoints and model.

Run layout (``RUN`` = the folder; deepracer-for-cloud's, so DeepRacer tools read it)::

    RUN/training_settings.json                      how the run was started (for resume)
    RUN/ip/hyperparameters.json                     DeepRacer's hyperparameter keys
    RUN/model/model_metadata.json                   DeepRacer's model metadata
    RUN/model/model.zip                             the submission file (at the end)
    RUN/0/training-simtrace/<iteration>-iteration.csv
    RUN/evaluation-<YYYYMMDDHHMMSS>/evaluation-simtrace/0-iteration.csv
    RUN/metrics.csv, RUN/reward_graph.png           console-style metrics and graph
    RUN/metrics/TrainingMetrics.json                DeepRacer's per-episode metrics
    RUN/training_params.yaml                        WORLD_NAME (the track) and race type
    RUN/checkpoints/last.pt, best.pt, fastest.pt    state dicts (torch, weights_only)
    RUN/models/<checkpoint>.zip, index.json         each checkpoint packed (league jobs)
    RUN/tensorboard/                                rsl-rl's TensorBoard events
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import torch

import arena
from agents import evaluate, export, networks
from agents.checkpoint import (
    CHECKPOINT_INDEX,
    CHECKPOINTS,
    Which,
    checkpoint_path,
    model_checkpoint,
    read_checkpoint,
)
from agents.deepracer_metrics import write_training_params
from agents.hyperparameters import Hyperparameters
from agents.model_metadata import DeepRacerMetadata, write_model_metadata
from agents.rewards import RewardFunction, resolve_reward
from agents.settings import TrainSettings, load_settings, save_settings, settings_path
from arena.config import RaceConfig
from tracks.catalog import get_track


def holds_run(path: str | Path) -> bool:
    """Whether ``path`` already holds a run's metrics or checkpoint."""
    return (Path(path) / "metrics.csv").exists() or checkpoint_path(path).exists()


def hyperparameters_path(path: str | Path) -> Path:
    """Where a run keeps its DeepRacer hyperparameters."""
    return Path(path) / "ip" / "hyperparameters.json"


@dataclass(frozen=True)
class Run:
    """A run folder with the settings and hyperparameters it trains with."""

    path: Path
    settings: TrainSettings
    hyperparameters: Hyperparameters

    @classmethod
    def load(cls, path: str | Path) -> Run:
        """The run stored in ``path`` (its hyperparameters: DeepRacer's defaults if it has
        no ``ip/hyperparameters.json``); FileNotFoundError if it holds no run."""
        path = Path(path)
        if not settings_path(path).is_file():
            raise FileNotFoundError(f"{path} holds no training run (no training_settings.json)")
        hp_file = hyperparameters_path(path)
        hp = Hyperparameters.load(hp_file) if hp_file.exists() else Hyperparameters()
        return cls(path, load_settings(path), hp)

    @property
    def stack_size(self) -> int:
        """Camera frames (and lidar scans) each observation stacks."""
        return self.hyperparameters.stack_size

    @property
    def model_zip(self) -> Path:
        """Where the run's submission file is written."""
        return self.path / "model" / "model.zip"

    @property
    def metrics_csv(self) -> Path:
        """The run's per-iteration metrics."""
        return self.path / "metrics.csv"

    @cached_property
    def reward(self) -> RewardFunction:
        """The run's reward function, resolved (and checked on sample params) once."""
        return resolve_reward(self.settings.reward_fn, self.settings.race_type)

    def write(self) -> None:
        """Write what the run starts with: settings (the network preset by name, never
        re-derived), hyperparameters, DeepRacer's model metadata and training params."""
        s = self.settings
        self.path.mkdir(parents=True, exist_ok=True)
        save_settings(self.path, s.model_copy(update={"network": s.preset}))
        self.hyperparameters.write(self.path)
        lidar = arena.CarConfig(name="car0").lidar_config
        meta = DeepRacerMetadata(
            action_space=s.action_space,
            sensors=s.sensors,
            neural_network=networks.deepracer_network_name(s.preset),
            lidar_config=lidar if any("sector" in x for x in s.sensors) else None,
        )
        (self.path / "model").mkdir(exist_ok=True)
        write_model_metadata(self.path / "model" / "model_metadata.json", meta)
        reverse = s.direction not in (None, get_track(s.track).direction)
        write_training_params(self.path, s.track, s.race_type, reverse)

    def checkpoint(self, device: str | torch.device = "cpu", which: Which | None = None) -> dict:
        """A checkpoint (default: the model's, ``best`` when there is one, else ``last``)."""
        return read_checkpoint(self.path, device, which or model_checkpoint(self.path))

    def best_score(self) -> tuple[float, ...] | None:
        """The evaluation score kept with ``best.pt`` (None without one)."""
        if not checkpoint_path(self.path, "best").exists():
            return None
        return tuple(self.checkpoint(which="best")["eval_score"])

    def fastest_lap(self) -> float | None:
        """The evaluation lap kept with ``fastest.pt`` (None without one)."""
        if not checkpoint_path(self.path, "fastest").exists():
            return None
        return float(self.checkpoint(which="fastest")["eval_best_lap"])

    def actor(self, device: str = "cpu", checkpoint: dict | None = None) -> torch.nn.Module:
        """The trained actor in eval mode (weights of ``checkpoint``, default the model's)."""
        s = self.settings
        actor = networks.build_actor(
            s.preset, s.sensors, s.action_space, stack_size=self.stack_size
        )
        actor.load_state_dict((checkpoint or self.checkpoint(device))["actor_state_dict"])
        return actor.to(device).eval()

    def evaluation_config(self, **changes: Any) -> RaceConfig:
        """The race the run's evaluations drive (its track, direction, race type with its
        boxes or bots, laps, seed and time limit, frames stacked as it trains), with
        ``changes`` to :func:`agents.evaluate.evaluation_config`'s keywords (another race
        type takes its own default boxes or bots)."""
        s = self.settings
        race = {
            "track": s.track,
            "race_type": s.race_type,
            "laps": s.eval_laps,
            "seed": s.seed,
            "time_limit_s": s.eval_time_limit,
            "direction": s.direction,
            **changes,
        }
        if race["race_type"] == s.race_type:
            race = {**s.race_rules(), **race}
        return evaluate.evaluation_config(
            sensors=s.sensors, action_space=s.action_space, stack_size=self.stack_size, **race
        )

    def evaluation_configs(self) -> list[RaceConfig]:
        """The races of one evaluation: :meth:`evaluation_config`'s on ``--track``, then,
        with ``--eval-also-tracks``, the same race on each ``--also-tracks`` track."""
        s = self.settings
        others = s.also_tracks if s.eval_also_tracks else ()
        return [self.evaluation_config(), *(self.evaluation_config(track=t) for t in others)]

    def checkpoints(self) -> list[dict[str, Any]]:
        """What each checkpoint the run keeps holds: its name (:data:`CHECKPOINTS`), what
        it is the best by, the iteration and training time it was taken at, and for an
        evaluation's checkpoint that evaluation's completion (%) and best lap."""
        kept = []
        for which, by in CHECKPOINTS.items():
            if not checkpoint_path(self.path, which).exists():
                continue
            ckpt = self.checkpoint(which=which)
            score = ckpt.get("eval_score")
            kept.append(
                {
                    "name": which,
                    "by": by,
                    "iteration": int(ckpt["iteration"]),
                    "minutes": round(float(ckpt["elapsed_s"]) / 60.0, 2),
                    "completion": float(score[0]) if score else None,
                    "best_lap": ckpt.get("eval_best_lap"),
                }
            )
        return kept

    def pack_checkpoints(self, folder: str | Path) -> list[dict[str, Any]]:
        """Pack each checkpoint the run keeps as ``folder/<name>.zip`` and list them in
        ``folder/index.json`` (:meth:`checkpoints`, each with its ``file``); returns the
        list. The model's own checkpoint is a copy of ``model.zip`` when it is packed, and
        checkpoints of the same iteration share one archive's bytes, so the same weights
        make the same league model."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        kept = self.checkpoints()
        packed: dict[int, Path] = {}
        if self.model_zip.is_file():
            model = read_checkpoint(self.path, which=model_checkpoint(self.path))
            packed[int(model["iteration"])] = self.model_zip
        for entry in kept:
            entry["file"] = f"{entry['name']}.zip"
            out = folder / entry["file"]
            same = packed.get(entry["iteration"])
            if same is not None:
                shutil.copyfile(same, out)
            else:
                packed[entry["iteration"]] = self.pack(out, entry["name"])
        (folder / CHECKPOINT_INDEX).write_text(json.dumps(kept, indent=1))
        return kept

    def pack(self, out: str | Path, which: Which | None = None) -> Path:
        """Pack the model as a submission at ``out`` (not validated here): the weights of
        checkpoint ``which``, by default the model's (its best evaluation's, else the last).

        The archive holds the exported actor, the run's DeepRacer metadata, its reward file
        when it still exists, ``metrics.csv`` and a training summary (with the best lap of
        the packed weights' evaluation).
        """
        s = self.settings
        ckpt = self.checkpoint(which=which)
        actor = self.actor(checkpoint=ckpt)
        reward = Path(s.reward_fn)
        reward_source = reward.read_text() if reward.suffix == ".py" and reward.is_file() else None
        return export.pack_model(
            out,
            export.export_onnx(actor, s.sensors, s.action_space, stack_size=self.stack_size),
            s.action_space,
            s.sensors,
            neural_network=networks.deepracer_network_name(s.preset),
            network_preset=s.preset,
            lidar=None,
            training_summary={
                "track": s.track,
                "race_type": s.race_type,
                "iterations": int(ckpt["iteration"]) + 1,  # up to the packed weights
                "minutes": round(float(ckpt["elapsed_s"]) / 60.0, 2),
                **({"best_lap": ckpt["eval_best_lap"]} if ckpt.get("eval_best_lap") else {}),
            },
            reward_source=reward_source,
            metrics_csv=self.metrics_csv if self.metrics_csv.is_file() else None,
            stack_size=self.stack_size,
        )
