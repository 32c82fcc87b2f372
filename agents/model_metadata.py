"""Read and write DeepRacer's ``model_metadata.json`` (the DeepRacer keys only).

A racer's existing DeepRacer file names the action space, the sensors (in DeepRacer
spelling), the network and the algorithm; training here starts from it and writes one
back. Files may carry more keys (Slipstream's own ``slipstream`` section, console
extras): reading ignores them. The action-space and sensor rules are ``arena``'s, shared
with ``submissions``, which validates uploaded files with its stricter schema.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pydantic import ValidationError

from agents.action_spaces import ActionSpace, ActionSpaceError, action_space_from_json
from arena.actions import DiscreteActionSpace, to_deepracer_metadata
from arena.config import validation_problems
from arena.sensors_spec import DEEPRACER_SENSOR, FROM_DEEPRACER_SENSOR, LidarConfig, check_sensors

DEEPRACER_VERSION = "5"
DEFAULT_NETWORK = "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"
"""DeepRacer's name for the "3-layer CNN" preset."""
DEFAULT_SENSORS = ("FRONT_FACING_CAMERA",)
"""What DeepRacer assumes when an old file has no ``sensor`` key."""
TrainingAlgorithm = Literal["clipped_ppo", "sac"]


class ModelMetadataError(ValueError):
    """A ``model_metadata.json`` that cannot be read or breaks the racing rules."""


@dataclass(frozen=True)
class DeepRacerMetadata:
    """The DeepRacer part of ``model_metadata.json``; ``sensors`` use arena's names."""

    action_space: ActionSpace
    sensors: tuple[str, ...]
    neural_network: str = DEFAULT_NETWORK
    lidar_config: LidarConfig | None = None
    training_algorithm: TrainingAlgorithm = "clipped_ppo"
    version: str = DEEPRACER_VERSION


def metadata_to_dict(meta: DeepRacerMetadata) -> dict[str, Any]:
    """The JSON object DeepRacer writes for ``meta`` (discrete actions carry ``index``)."""
    data: dict[str, Any] = {
        **to_deepracer_metadata(meta.action_space),
        "sensor": [DEEPRACER_SENSOR[s] for s in check_sensors(meta.sensors)],
        "neural_network": meta.neural_network,
        "training_algorithm": meta.training_algorithm,
        "version": meta.version,
    }
    if meta.lidar_config is not None:
        data["lidar_config"] = meta.lidar_config.model_dump()
    return data


def _sensors(raw: Any) -> tuple[str, ...]:
    if not isinstance(raw, list) or not all(isinstance(s, str) for s in raw):
        raise ModelMetadataError(f"sensor must be a list of sensor names, got {raw!r}")
    unknown = [s for s in raw if s not in FROM_DEEPRACER_SENSOR]
    if unknown:
        raise ModelMetadataError(
            f"unknown sensor(s) {unknown}; DeepRacer sensors are {sorted(FROM_DEEPRACER_SENSOR)}"
        )
    try:
        return check_sensors([FROM_DEEPRACER_SENSOR[s] for s in raw])
    except ValueError as exc:
        raise ModelMetadataError(f"sensor: {exc}") from None


def _lidar_config(raw: Any) -> LidarConfig | None:
    if raw is None:
        return None
    try:
        return LidarConfig.model_validate(raw)
    except ValidationError as exc:
        raise ModelMetadataError(f"lidar_config: {validation_problems(exc)}") from None


def metadata_from_dict(data: Any) -> DeepRacerMetadata:
    """Parse a decoded ``model_metadata.json``; raises :class:`ModelMetadataError`."""
    if not isinstance(data, dict):
        raise ModelMetadataError(f"model_metadata.json must hold a JSON object, got {data!r:.80}")
    if "action_space" not in data:
        raise ModelMetadataError("model_metadata.json has no 'action_space'")
    try:
        space = action_space_from_json(data)
    except ActionSpaceError as exc:
        raise ModelMetadataError(f"action_space: {exc}") from None
    algorithm = data.get("training_algorithm", "clipped_ppo")
    if algorithm not in ("clipped_ppo", "sac"):
        raise ModelMetadataError(
            f"training_algorithm must be 'clipped_ppo' or 'sac', got {algorithm!r}"
        )
    if algorithm == "sac" and isinstance(space, DiscreteActionSpace):
        raise ModelMetadataError("training_algorithm 'sac' needs a continuous action space")
    network = data.get("neural_network", DEFAULT_NETWORK)
    if not isinstance(network, str) or not network:
        raise ModelMetadataError(f"neural_network must be a non-empty name, got {network!r}")
    version = data.get("version", DEEPRACER_VERSION)
    if isinstance(version, bool) or not isinstance(version, str | int | float):
        raise ModelMetadataError(f"version must be a string or number, got {version!r}")
    return DeepRacerMetadata(
        action_space=space,
        sensors=_sensors(data.get("sensor", list(DEFAULT_SENSORS))),
        neural_network=network,
        lidar_config=_lidar_config(data.get("lidar_config")),
        training_algorithm=algorithm,
        version=str(version),
    )


def read_model_metadata(path: str | Path) -> DeepRacerMetadata:
    """Read a ``model_metadata.json`` file; raises :class:`ModelMetadataError`."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ModelMetadataError(f"cannot read {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ModelMetadataError(f"{path} is not UTF-8 text") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelMetadataError(f"{path} is not valid JSON: {exc}") from None
    return metadata_from_dict(data)


def training_metadata(spec: str) -> DeepRacerMetadata | None:
    """The ``model_metadata.json`` an action-space spec names, or ``None`` for other specs.

    A file is metadata when it holds a JSON object with an ``action_space`` key (a bare
    action-space file is not). Training runs clipped PPO only, so a file asking for SAC is
    refused with a :class:`ModelMetadataError` that says so.
    """
    path = Path(spec.strip())
    if path.suffix.lower() != ".json" or not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None  # the action-space parser reports unreadable files
    if not isinstance(data, dict) or "action_space" not in data:
        return None
    meta = metadata_from_dict(data)
    if meta.training_algorithm == "sac":
        raise ModelMetadataError(
            f"{path} asks for training_algorithm 'sac', but Slipstream trains with clipped PPO "
            "only (rsl-rl has no SAC); set \"training_algorithm\": \"clipped_ppo\" in the file "
            "to train this action space with PPO"
        )
    return meta


def write_model_metadata(path: str | Path, meta: DeepRacerMetadata) -> Path:
    """Write ``meta`` as ``model_metadata.json`` (two-space indent); returns the path."""
    path = Path(path)
    path.write_text(json.dumps(metadata_to_dict(meta), indent=2) + "\n", encoding="utf-8")
    return path
