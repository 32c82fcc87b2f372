"""Submission I/O costs: validate time, file sizes, per-step inference latency.

Builds the two presets racers know ("3-layer CNN" on the camera, dense 256-256 on the
lidar), exports them with ``torch.onnx.export``, packs and validates them, then times
batch-1 inference on one thread with onnxruntime and with torch eager.

Run: ``.venv/bin/python benchmarks/submission_io.py``
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from harness import ResultTable, add_record_option, summary, time_calls, write
from torch import nn

from arena.actions import default_discrete_space
from arena.sensors_spec import observation_space
from submissions import load_policy, pack, validate

RUNS = 300
WARMUP = 30


class ThreeLayerCNN(nn.Module):
    """DeepRacer's "3-layer CNN": conv 32/8/4, 64/4/2, 64/3/1, dense 512, on 120x160x1."""

    def __init__(self, n_out: int) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(1, 32, 8, stride=4), nn.ReLU(),
            nn.Conv2d(32, 64, 4, stride=2), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=1), nn.ReLU(),
            nn.Flatten(), nn.Linear(64 * 11 * 16, 512), nn.ReLU(), nn.Linear(512, n_out),
        )  # fmt: skip

    def forward(self, camera: torch.Tensor) -> torch.Tensor:
        return self.net(camera.to(torch.float32).permute(0, 3, 1, 2) / 255.0)


class LidarMLP(nn.Module):
    """The lidar preset: dense 256-256 on 64 beams."""

    def __init__(self, n_out: int) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(64, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, n_out)
        )

    def forward(self, lidar: torch.Tensor) -> torch.Tensor:
        return self.net(lidar)


def _export(module: nn.Module, example: torch.Tensor, name: str) -> bytes:
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        path = Path(tmp) / "policy.onnx"
        torch.onnx.export(
            module,
            (example,),
            path,
            input_names=[name],
            output_names=["logits"],
            dynamic_shapes=({0: torch.export.Dim.DYNAMIC},),
            external_data=False,
        )
        return path.read_bytes()


def _median_ms(step: Callable[[], object]) -> float:
    return 1000.0 * summary(time_calls(step, RUNS, warmup=WARMUP)).median


def _row(label: str, module: nn.Module, sensor: str, example: torch.Tensor, tmp: Path) -> list:
    space = default_discrete_space()
    policy_bytes = _export(module.eval(), example, sensor)
    archive = pack(tmp / f"{sensor}.zip", policy_bytes, space, [sensor], network_preset=label)
    validate_s = min(time_calls(lambda: validate(archive), 3))
    report = validate(archive)
    assert report.ok, report.problems
    obs_space = observation_space((sensor,))
    obs_space.seed(0)
    obs = obs_space.sample()
    policy = load_policy(archive)
    ort_ms = _median_ms(lambda: policy.act(obs))
    tensor = torch.from_numpy(np.asarray(obs[sensor]))[None]
    with torch.inference_mode():
        torch_ms = _median_ms(lambda: int(module(tensor).argmax()))
    params = sum(p.numel() for p in module.parameters())
    return [label, f"{params / 1e6:.2f} M", len(policy_bytes), archive.stat().st_size,
            validate_s * 1000.0, ort_ms, torch_ms]  # fmt: skip


def main() -> None:
    """Measure both presets; write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_record_option(parser)
    args = parser.parse_args()
    torch.manual_seed(0)
    torch.set_num_threads(1)
    n = default_discrete_space().n
    cases = [
        ("3-layer CNN (camera)", ThreeLayerCNN(n), "camera",
         torch.randint(0, 256, (2, 120, 160, 1), dtype=torch.uint8)),
        ("dense 256-256 (lidar)", LidarMLP(n), "lidar", torch.rand(2, 64) * 0.85 + 0.15),
    ]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        rows = [_row(label, m, s, x, Path(tmp)) for label, m, s, x in cases]
    header = ["policy", "params", "onnx bytes", "zip bytes", "validate ms",
              "onnxruntime ms/step", "torch eager ms/step"]  # fmt: skip
    table = ResultTable("Submission I/O costs", header)
    table.notes.append(
        f"batch 1, one thread, median of {RUNS} steps after {WARMUP} warm-up; validate = best of 3"
    )
    for label, params, onnx_b, zip_b, val_ms, ort_ms, torch_ms in rows:
        table.add_row(label, params, f"{onnx_b:,}", f"{zip_b:,}", f"{val_ms:.0f}",
                      f"{ort_ms:.3f}", f"{torch_ms:.3f}")  # fmt: skip
    write(table, args.record)


if __name__ == "__main__":
    main()
