"""Export a trained actor to ONNX in the submission convention, and pack ``model.zip``.

The graph takes one input per sensor, named after it, with a leading batch dimension:
raw ``uint8`` HWC images (cast, scaled to ``[0, 1]`` and transposed inside the graph) and
float32 lidar vectors, each holding ``stack_size`` frames along its last axis. Its one
output is ``(batch, n)`` logits for a discrete space or ``(batch, 2)`` mean actions clipped
to ``[-1, 1]`` for a continuous one (``docs/model-format.md``).
"""

from __future__ import annotations

import contextlib
import copy
import io
import logging
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from arena.actions import ContinuousActionSpace, DiscreteActionSpace
from arena.sensors_spec import IMAGE_SENSORS, LidarConfig, check_sensors, sensor_space
from submissions import pack

OPSET = 18


class SubmissionPolicy(nn.Module):
    """The actor's deterministic path, reading raw sensor arrays."""

    def __init__(self, actor: nn.Module, sensors: tuple[str, ...], discrete: bool) -> None:
        super().__init__()
        self.sensors = list(check_sensors(sensors))
        self.discrete = discrete
        self.vector_groups = list(actor.obs_groups)
        self.image_groups = list(getattr(actor, "obs_groups_2d", []))
        self.normalizer = copy.deepcopy(actor.obs_normalizer)
        self.cnns = nn.ModuleList([copy.deepcopy(actor.cnns[g]) for g in self.image_groups])
        self.mlp = copy.deepcopy(actor.mlp)

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        """Logits (discrete) or clipped mean actions (continuous)."""
        named = dict(zip(self.sensors, inputs, strict=True))
        parts = []
        if self.vector_groups:
            vector = torch.cat([named[g].float() for g in self.vector_groups], dim=-1)
            parts.append(self.normalizer(vector))
        for group, cnn in zip(self.image_groups, self.cnns, strict=True):
            image = named[group].float().permute(0, 3, 1, 2) / 255.0
            parts.append(cnn(image))
        out = self.mlp(torch.cat(parts, dim=-1))
        return out if self.discrete else out.clamp(-1.0, 1.0)


def example_inputs(
    sensors: tuple[str, ...],
    lidar: LidarConfig | None = None,
    batch: int = 1,
    seed: int = 0,
    stack_size: int = 1,
) -> dict[str, np.ndarray]:
    """Random valid raw observations (uint8 images, float32 vectors, ``stack_size`` frames
    stacked) with a batch dim."""
    rng = np.random.default_rng(seed)
    out = {}
    for name in check_sensors(sensors):
        space = sensor_space(name, lidar, stack_size)
        if name in IMAGE_SENSORS:
            out[name] = rng.integers(0, 256, (batch, *space.shape), dtype=np.uint8)
        else:
            low, high = float(space.low.min()), float(space.high.max())
            out[name] = rng.uniform(low, high, (batch, *space.shape)).astype(np.float32)
    return out


def export_onnx(
    actor: nn.Module,
    sensors: tuple[str, ...] | list[str],
    action_space: DiscreteActionSpace | ContinuousActionSpace,
    lidar: LidarConfig | None = None,
    stack_size: int = 1,
) -> bytes:
    """ONNX bytes of the actor in the submission convention (dynamic batch)."""
    sensors = check_sensors(sensors)
    module = SubmissionPolicy(actor, sensors, isinstance(action_space, DiscreteActionSpace))
    module = module.to("cpu").eval()
    inputs = example_inputs(sensors, lidar, 2, stack_size=stack_size)
    examples = tuple(torch.from_numpy(a) for a in inputs.values())
    dims = tuple({0: torch.export.Dim.DYNAMIC} for _ in examples)
    logging.getLogger("torch.onnx").setLevel(logging.ERROR)
    with (
        tempfile.TemporaryDirectory() as tmp,
        contextlib.redirect_stdout(io.StringIO()),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore", FutureWarning)
        path = Path(tmp) / "policy.onnx"
        torch.onnx.export(
            module,
            examples,
            str(path),
            input_names=list(sensors),
            output_names=["logits" if module.discrete else "actions"],
            dynamic_shapes=(dims,),
            opset_version=OPSET,
            external_data=False,
        )
        return path.read_bytes()


def pack_model(
    out_path: str | Path,
    graph: bytes,
    action_space: DiscreteActionSpace | ContinuousActionSpace,
    sensors: tuple[str, ...] | list[str],
    *,
    neural_network: str,
    network_preset: str,
    lidar: LidarConfig | None,
    training_summary: dict[str, Any],
    reward_source: str | None,
    metrics_csv: Path | None,
    stack_size: int = 1,
) -> Path:
    """Pack ``model.zip`` with ``submissions.pack``."""
    return pack(
        out_path,
        graph,
        action_space,
        tuple(sensors),
        neural_network=neural_network,
        lidar_config=lidar if any("sector" in s for s in sensors) else None,
        training_summary=training_summary,
        reward_function=reward_source,
        metrics_csv=metrics_csv if metrics_csv is not None and metrics_csv.exists() else None,
        network_preset=network_preset,
        stack_size=stack_size,
    )
