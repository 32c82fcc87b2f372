"""``validate``: the one verdict on a submission, shared by the racer's CLI and the server.

Stages run cheapest first and stop at the first that fails: archive (with the bounds of
``metrics.csv``), metadata, graph, behaviour. Every failure becomes a
:class:`~submissions.format.Problem`; nothing raises.
"""

from __future__ import annotations

import hashlib
from datetime import datetime
from pathlib import Path

from pydantic import BaseModel, ConfigDict

from arena.actions import ActionSpace
from arena.sensors_spec import LidarConfig
from submissions.archive import read_archive
from submissions.format import (
    METADATA_MEMBER,
    METRICS_MEMBER,
    POLICY_MEMBER,
    REWARD_MEMBER,
    InputSpec,
    Limits,
    Problem,
    short,
)
from submissions.metadata import CheckedMetadata, JsonScalar, OutputSpec, check_metadata
from submissions.metrics_csv import check_metrics
from submissions.onnx_checks import check_behaviour, check_graph

DEFAULT_LIMITS = Limits()


class ModelInfo(BaseModel):
    """What a valid (or metadata-valid) submission declares, plus what was measured."""

    model_config = ConfigDict(frozen=True)

    archive_sha256: str
    archive_bytes: int
    format_version: int
    action_space: ActionSpace
    sensors: tuple[str, ...]
    lidar_config: LidarConfig | None
    observation: tuple[InputSpec, ...]
    output: OutputSpec
    neural_network: str
    network_preset: str | None
    stack_size: int = 1
    training_algorithm: str
    training_summary: dict[str, JsonScalar]
    created_at: datetime
    policy_sha256: str
    policy_bytes: int
    has_reward_function: bool
    has_metrics: bool
    latency_ms: float | None = None


class ValidationReport(BaseModel):
    """The verdict: ``ok`` when there are no problems. ``info`` is set once the archive and
    the metadata passed, even if a later stage failed."""

    model_config = ConfigDict(frozen=True)

    problems: tuple[Problem, ...] = ()
    info: ModelInfo | None = None

    @property
    def ok(self) -> bool:
        """True when the submission passed every check that ran."""
        return not self.problems


class InvalidSubmission(ValueError):
    """Raised by :func:`submissions.load_policy` for a file that fails validation."""

    def __init__(self, report: ValidationReport) -> None:
        self.report = report
        listed = "; ".join(str(p) for p in report.problems)
        super().__init__(f"invalid submission: {listed}")


Source = str | Path | bytes | bytearray | memoryview


def read_source(source: Source, limits: Limits) -> bytes | Problem:
    """The archive's bytes, refusing (as a Problem) files over the size cap before reading."""
    if isinstance(source, bytes | bytearray | memoryview):
        return bytes(source)
    try:
        path = Path(source)
        size = path.stat().st_size
        if size > limits.max_archive_bytes:
            return Problem(
                field="archive",
                expected=f"at most {limits.max_archive_bytes} bytes",
                found=f"{size} bytes",
                message="The archive is larger than the upload limit.",
            )
        return path.read_bytes()
    except Exception as exc:
        return Problem(
            field="archive",
            expected="a readable file",
            found=short(f"{type(exc).__name__}: {exc}"),
            message="The file could not be read.",
        )


def _info(data: bytes, members: dict[str, bytes], checked: CheckedMetadata) -> ModelInfo:
    meta = checked.metadata
    section = meta.slipstream
    return ModelInfo(
        archive_sha256=hashlib.sha256(data).hexdigest(),
        archive_bytes=len(data),
        format_version=section.format_version,
        action_space=checked.action_space,
        sensors=checked.sensors,
        lidar_config=checked.lidar_config,
        observation=section.observation,
        output=section.output,
        neural_network=meta.neural_network,
        network_preset=section.network_preset,
        stack_size=section.stack_size,
        training_algorithm=meta.training_algorithm,
        training_summary=section.training,
        created_at=section.created_at,
        policy_sha256=section.policy_sha256,
        policy_bytes=len(members[POLICY_MEMBER]),
        has_reward_function=REWARD_MEMBER in members,
        has_metrics=METRICS_MEMBER in members,
    )


def _validate(source: Source, limits: Limits, run_policy: bool) -> ValidationReport:
    data = read_source(source, limits)
    if isinstance(data, Problem):
        return ValidationReport(problems=(data,))
    members, problems = read_archive(data, limits)
    if members is None:
        return ValidationReport(problems=tuple(problems))
    if METRICS_MEMBER in members and (problems := check_metrics(members[METRICS_MEMBER], limits)):
        return ValidationReport(problems=tuple(problems))
    policy = members[POLICY_MEMBER]
    checked, problems = check_metadata(members[METADATA_MEMBER], policy, limits)
    if checked is None:
        return ValidationReport(problems=tuple(problems))
    info = _info(data, members, checked)
    problems = check_graph(policy, checked, limits)
    if problems or not run_policy:
        return ValidationReport(problems=tuple(problems), info=info)
    latency, problems = check_behaviour(policy, checked, limits)
    info = info.model_copy(update={"latency_ms": latency})
    return ValidationReport(problems=tuple(problems), info=info)


def validate(
    source: Source,
    limits: Limits = DEFAULT_LIMITS,
    *,
    run_policy: bool = True,
) -> ValidationReport:
    """Check a submission (a path or the archive's bytes) without executing anything in it.

    ``run_policy=False`` skips the behaviour stage (no onnxruntime session, no latency).
    Never raises for bad input: every failure is a Problem in the report.
    """
    try:
        return _validate(source, limits, run_policy)
    except Exception as exc:  # a last net: a validator bug must not become a server error
        problem = Problem(
            field="archive",
            expected="a file the validator can judge",
            found=short(f"{type(exc).__name__}: {exc}", 200),
            message="The validator failed unexpectedly on this file; please report it.",
        )
        return ValidationReport(problems=(problem,))
