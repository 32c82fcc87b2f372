"""The submission file format, version 1: member names, conventions, limits and problems.

Everything a reader of ``docs/model-format.md`` needs in code lives here; the other
modules of the package check or build archives against these definitions.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from arena.sensors_spec import LidarConfig, sensor_space

FORMAT_VERSION = 1
SUPPORTED_FORMAT_VERSIONS: tuple[int, ...] = (1,)

METADATA_MEMBER = "model_metadata.json"
POLICY_MEMBER = "policy.onnx"
REWARD_MEMBER = "reward_function.py"
METRICS_MEMBER = "metrics.csv"
REQUIRED_MEMBERS: tuple[str, ...] = (METADATA_MEMBER, POLICY_MEMBER)
OPTIONAL_MEMBERS: tuple[str, ...] = (REWARD_MEMBER, METRICS_MEMBER)
ALLOWED_MEMBERS: tuple[str, ...] = REQUIRED_MEMBERS + OPTIONAL_MEMBERS

OutputConvention = Literal["logits", "action"]
DISCRETE_OUTPUT: OutputConvention = "logits"
CONTINUOUS_OUTPUT: OutputConvention = "action"

MiB = 1024 * 1024
KiB = 1024
MEMORY_WORDS = ("MemoryError", "bad_alloc", "bad allocation", "Failed to allocate", "std::bad")
"""Words in an error's text that say it ran out of memory (onnxruntime, C++, Python)."""


class Limits(BaseModel):
    """Every cap the validator enforces; the defaults are the league's (see the format doc)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    max_archive_bytes: int = Field(default=50 * MiB, gt=0)
    max_members: int = Field(default=8, gt=0)
    max_total_uncompressed_bytes: int = Field(default=120 * MiB, gt=0)
    max_compression_ratio: float = Field(default=100.0, gt=1.0)
    ratio_check_min_bytes: int = Field(default=1 * MiB, ge=0)
    max_metadata_bytes: int = Field(default=64 * KiB, gt=0)
    max_policy_bytes: int = Field(default=100 * MiB, gt=0)
    max_reward_function_bytes: int = Field(default=256 * KiB, gt=0)
    max_metrics_bytes: int = Field(default=16 * MiB, gt=0)
    max_metrics_line_bytes: int = Field(default=4 * KiB, gt=0)
    max_metrics_columns: int = Field(default=64, gt=0)
    max_metrics_name_chars: int = Field(default=64, gt=0)
    max_metrics_rows: int = Field(default=100_000, gt=0)
    max_metrics_cells: int = Field(default=1_000_000, gt=0)
    min_opset: int = Field(default=13, ge=1)
    max_opset: int = Field(default=21, ge=1)
    max_nodes: int = Field(default=2000, gt=0)
    max_parameters: int = Field(default=25_000_000, gt=0)
    max_computed_bytes: int = Field(default=256 * MiB, gt=0)
    max_step_macs: int = Field(default=2_000_000_000, gt=0)
    smoke_batch_sizes: tuple[int, ...] = (1, 3, 8)
    smoke_seed: int = 0
    latency_warmup_runs: int = Field(default=5, ge=0)
    latency_runs: int = Field(default=30, gt=0)
    max_latency_ms: float = Field(default=20.0, gt=0.0)
    max_run_seconds: float = Field(default=2.0, gt=0.0)

    def member_cap(self, name: str) -> int:
        """The uncompressed size cap of one allowed member."""
        return {
            METADATA_MEMBER: self.max_metadata_bytes,
            POLICY_MEMBER: self.max_policy_bytes,
            REWARD_MEMBER: self.max_reward_function_bytes,
            METRICS_MEMBER: self.max_metrics_bytes,
        }[name]


class Problem(BaseModel):
    """One reason a submission is refused: where, what was expected, what was found, why."""

    model_config = ConfigDict(frozen=True)

    field: str
    expected: str
    found: str
    message: str

    def __str__(self) -> str:
        return f"{self.field}: {self.message} (expected {self.expected}; found {self.found})"


class InputSpec(BaseModel):
    """One graph input: the sensor it carries and its per-sample shape and dtype."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(max_length=64)
    shape: tuple[int, ...] = Field(max_length=8)
    dtype: Literal["uint8", "float32"]


def observation_spec(sensors: tuple[str, ...], lidar: LidarConfig | None = None) -> list[InputSpec]:
    """The graph inputs a policy for ``sensors`` must declare (batch dimension excluded)."""
    specs = []
    for name in sensors:
        box = sensor_space(name, lidar)
        dtype = "uint8" if box.dtype == np.uint8 else "float32"
        specs.append(InputSpec(name=name, shape=tuple(int(d) for d in box.shape), dtype=dtype))
    return specs


def short(value: object, limit: int = 80) -> str:
    """A one-line, length-capped rendering of an untrusted value for a Problem."""
    text = value if isinstance(value, str) else repr(value)
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[: limit - 3] + "..."
