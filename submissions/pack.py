"""Write a submission archive from its parts, byte-for-byte reproducibly."""

from __future__ import annotations

import zipfile
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

from arena.actions import from_deepracer_metadata, parse_action_space
from arena.sensors_spec import FROM_DEEPRACER_SENSOR, LidarConfig, check_sensors
from submissions.format import METADATA_MEMBER, METRICS_MEMBER, POLICY_MEMBER, REWARD_MEMBER
from submissions.metadata import ActionSpace, JsonScalar, build_metadata, dump_metadata

ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)
DEFAULT_NEURAL_NETWORK = "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"


def _bytes(part: bytes | str | Path, text: bool) -> bytes:
    """A part given as bytes, as a path, or (for text members) as the text itself."""
    if isinstance(part, bytes):
        return part
    if isinstance(part, Path) or not text:
        return Path(part).read_bytes()
    return part.encode()


def _action_space(space: ActionSpace | dict[str, Any]) -> ActionSpace:
    if isinstance(space, dict) and "action_space" in space:
        return from_deepracer_metadata(space)
    return parse_action_space(space)


def _member(name: str) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=ZIP_EPOCH)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.create_system = 3
    info.external_attr = 0o100644 << 16
    return info


def pack(
    out_path: str | Path,
    policy_onnx: bytes | Path,
    action_space: ActionSpace | dict[str, Any],
    sensors: tuple[str, ...] | list[str],
    *,
    neural_network: str = DEFAULT_NEURAL_NETWORK,
    training_algorithm: Literal["clipped_ppo", "sac"] = "clipped_ppo",
    lidar_config: LidarConfig | dict[str, Any] | None = None,
    training_summary: dict[str, JsonScalar] | None = None,
    reward_function: str | Path | None = None,
    metrics_csv: bytes | str | Path | None = None,
    network_preset: str | None = None,
    created_at: datetime | None = None,
    stack_size: int = 1,
) -> Path:
    """Write a format-1 submission archive and return its path.

    ``action_space`` is a space, its dict form, or DeepRacer's metadata keys; ``sensors``
    use Slipstream or DeepRacer names. A ``reward_function`` or ``metrics_csv`` given as
    ``str`` is the content (a ``Path`` is read). The same parts and ``created_at``
    (default: now, whole seconds, UTC) give the same bytes. ``stack_size`` is the number of
    frames of each sensor the graph reads (its inputs' last axis holds them all: a camera
    ``120 x 160 x stack_size``). Metadata values are checked
    (pydantic or ``ValueError``); the graph is not: run :func:`submissions.validate`.
    """
    policy = _bytes(policy_onnx, text=False)
    names = check_sensors([FROM_DEEPRACER_SENSOR.get(s, s) for s in sensors])
    lidar = LidarConfig.model_validate(lidar_config) if lidar_config is not None else None
    meta = build_metadata(
        policy=policy,
        action_space=_action_space(action_space),
        sensors=names,
        neural_network=neural_network,
        training_algorithm=training_algorithm,
        lidar_config=lidar,
        network_preset=network_preset,
        training_summary=training_summary,
        created_at=created_at or datetime.now(UTC).replace(microsecond=0),
        stack_size=stack_size,
    )
    members = [(METADATA_MEMBER, dump_metadata(meta)), (POLICY_MEMBER, policy)]
    if reward_function is not None:
        members.append((REWARD_MEMBER, _bytes(reward_function, text=True)))
    if metrics_csv is not None:
        members.append((METRICS_MEMBER, _bytes(metrics_csv, text=True)))
    out = Path(out_path)
    with zipfile.ZipFile(out, "w") as zf:
        for name, content in members:
            zf.writestr(_member(name), content, compresslevel=9)
    return out
