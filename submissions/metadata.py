"""``model_metadata.json``: the schema (DeepRacer keys plus a ``slipstream`` section),
parsing with human-readable problems, and building it for :func:`submissions.pack`."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from arena.actions import (
    ContinuousActionSpace,
    DiscreteActionSpace,
    from_deepracer_metadata,
    to_deepracer_metadata,
)
from arena.sensors_spec import (
    DEEPRACER_SENSOR,
    FROM_DEEPRACER_SENSOR,
    MAX_STACK_SIZE,
    LidarConfig,
    check_sensors,
    sensor_space,
)
from submissions.format import (
    CONTINUOUS_OUTPUT,
    DISCRETE_OUTPUT,
    FORMAT_VERSION,
    METADATA_MEMBER,
    SUPPORTED_FORMAT_VERSIONS,
    InputSpec,
    Limits,
    OutputConvention,
    Problem,
    observation_spec,
    short,
)

DEEPRACER_VERSION = "5"
JsonScalar = str | int | float | bool | None
ActionSpace = DiscreteActionSpace | ContinuousActionSpace


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class OutputSpec(_Strict):
    """The single graph output: ``logits`` (discrete, size n) or ``action`` (continuous, 2)."""

    convention: OutputConvention
    size: int = Field(ge=1, le=64)


class SlipstreamSection(_Strict):
    """Slipstream's own part of the metadata file."""

    format_version: int
    observation: tuple[InputSpec, ...] = Field(min_length=1, max_length=5)
    output: OutputSpec
    network_preset: str | None = Field(default=None, max_length=64)
    stack_size: int = Field(default=1, ge=1, le=MAX_STACK_SIZE)
    """Frames of each sensor the graph reads, stacked along the last axis (absent: 1)."""
    training: dict[str, JsonScalar] = Field(default_factory=dict, max_length=32)
    created_at: datetime
    policy_sha256: str = Field(pattern=r"^[0-9a-f]{64}$")


class ModelMetadata(_Strict):
    """The whole ``model_metadata.json`` (action space still raw; see :func:`check_metadata`)."""

    action_space: list[dict[str, Any]] | dict[str, Any] = Field(max_length=64)
    action_space_type: Literal["discrete", "continuous"]
    sensor: tuple[str, ...] = Field(min_length=1, max_length=5)
    neural_network: str = Field(max_length=64, pattern=r"^[A-Za-z0-9_.\- ]+$")
    training_algorithm: Literal["clipped_ppo", "sac"]
    version: str | int
    lidar_config: LidarConfig | None = None
    slipstream: SlipstreamSection


def stacked_observation_spec(
    sensors: tuple[str, ...], lidar: LidarConfig | None, stack_size: int = 1
) -> tuple[InputSpec, ...]:
    """The graph inputs for ``sensors`` with ``stack_size`` frames each (batch excluded)."""
    specs = observation_spec(sensors, lidar)
    if stack_size == 1:
        return tuple(specs)

    def shape(name: str) -> tuple[int, ...]:
        return tuple(int(d) for d in sensor_space(name, lidar, stack_size).shape)

    return tuple(s.model_copy(update={"shape": shape(s.name)}) for s in specs)


@dataclass(frozen=True)
class CheckedMetadata:
    """Metadata that passed every check, with the action space and sensors resolved."""

    metadata: ModelMetadata
    action_space: ActionSpace
    sensors: tuple[str, ...]
    lidar_config: LidarConfig | None


def _problem(path: str, expected: str, found: str, message: str) -> Problem:
    return Problem(
        field=f"{METADATA_MEMBER}:{path}", expected=expected, found=found, message=message
    )


def _path(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "(root)"


_EXPECTED_BY_CTX = {"le": "<= {}", "ge": ">= {}", "lt": "< {}", "gt": "> {}"}


def _expected(err: Any) -> str:
    ctx = err.get("ctx") or {}
    for key, template in _EXPECTED_BY_CTX.items():
        if key in ctx:
            return template.format(ctx[key])
    if "max_length" in ctx:
        return f"length at most {ctx['max_length']}"
    if "min_length" in ctx:
        return f"length at least {ctx['min_length']}"
    if "expected" in ctx:
        return str(ctx["expected"])
    if "pattern" in ctx:
        return f"text matching {ctx['pattern']}"
    return {"missing": "a value", "extra_forbidden": "no such key"}.get(err["type"], err["msg"])


def _from_errors(errors: list[Any], prefix: tuple[Any, ...] = ()) -> list[Problem]:
    problems = []
    for err in errors:
        found = "nothing" if err["type"] == "missing" else short(err.get("input"))
        message = err["msg"][0].upper() + err["msg"][1:].rstrip(".") + "."
        problems.append(_problem(_path(prefix + tuple(err["loc"])), _expected(err), found, message))
    return problems


def _action_space_problems(exc: ValidationError) -> list[Problem]:
    """Map arena's errors (locs like ``('discrete', 'actions', 2, 'speed')``) to file paths."""
    errors = []
    for err in exc.errors():
        loc = list(err["loc"])
        if loc and loc[0] in ("discrete", "continuous"):
            loc = loc[1:]
        if loc and loc[0] == "actions":
            loc = loc[1:]
        errors.append({**err, "loc": tuple(loc)})
    return _from_errors(errors, ("action_space",))


def _load_json(raw: bytes) -> Any:
    def no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        keys = [k for k, _ in pairs]
        if len(set(keys)) != len(keys):
            raise ValueError(f"duplicate key in object: {short(keys)}")
        return dict(pairs)

    def no_constants(name: str) -> Any:
        raise ValueError(f"{name} is not valid JSON")

    return json.loads(raw, object_pairs_hook=no_duplicates, parse_constant=no_constants)


def _version_problem(data: Any) -> Problem | None:
    """A first look at ``format_version`` alone: a future version may change everything else."""
    section = data.get("slipstream") if isinstance(data, dict) else None
    version = section.get("format_version") if isinstance(section, dict) else None
    if isinstance(version, int) and version not in SUPPORTED_FORMAT_VERSIONS:
        return _problem(
            "slipstream.format_version",
            f"one of {list(SUPPORTED_FORMAT_VERSIONS)}",
            short(version),
            "This validator does not know that format version.",
        )
    return None


def _sensors(meta: ModelMetadata) -> tuple[tuple[str, ...] | None, list[Problem]]:
    unknown = [
        _problem(
            f"sensor[{i}]",
            f"one of {sorted(FROM_DEEPRACER_SENSOR)}",
            short(name),
            "Unknown sensor.",
        )
        for i, name in enumerate(meta.sensor)
        if name not in FROM_DEEPRACER_SENSOR
    ]
    if unknown:
        return None, unknown
    try:
        return check_sensors([FROM_DEEPRACER_SENSOR[s] for s in meta.sensor]), []
    except ValueError as exc:
        return None, [
            _problem("sensor", "a valid sensor combination", short(meta.sensor), str(exc))
        ]


def _consistency(
    meta: ModelMetadata, space: ActionSpace, sensors: tuple[str, ...], policy: bytes
) -> list[Problem]:
    section = meta.slipstream
    problems = _observation_problems(section, sensors, meta.lidar_config)
    if isinstance(space, DiscreteActionSpace):
        expected_out = OutputSpec(convention=DISCRETE_OUTPUT, size=space.n)
    else:
        expected_out = OutputSpec(convention=CONTINUOUS_OUTPUT, size=2)
    if section.output != expected_out:
        problems.append(
            _problem(
                "slipstream.output",
                short(expected_out.model_dump()),
                short(section.output.model_dump()),
                "The output convention does not match the action space.",
            )
        )
    if meta.training_algorithm == "sac" and isinstance(space, DiscreteActionSpace):
        problems.append(
            _problem(
                "training_algorithm",
                "clipped_ppo for a discrete action space",
                "sac",
                "SAC supports continuous action spaces only.",
            )
        )
    digest = hashlib.sha256(policy).hexdigest()
    if section.policy_sha256 != digest:
        problems.append(
            _problem(
                "slipstream.policy_sha256",
                digest,
                section.policy_sha256,
                "The policy file does not match the hash in the metadata.",
            )
        )
    return problems


def _observation_problems(
    section: SlipstreamSection, sensors: tuple[str, ...], lidar: LidarConfig | None
) -> list[Problem]:
    """The observation spec against the sensors and stack size: one problem per input whose
    shape alone is wrong, else one for the whole spec."""
    expected = stacked_observation_spec(sensors, lidar, section.stack_size)
    if section.observation == expected:
        return []
    found = section.observation
    same_but_shapes = len(found) == len(expected) and all(
        f.name == e.name and f.dtype == e.dtype for f, e in zip(found, expected, strict=True)
    )
    if same_but_shapes:
        return [
            _problem(
                f"slipstream.observation[{i}].shape",
                short(e.shape),
                short(f.shape),
                f"The {e.name} input's shape does not match the sensor with "
                f"stack_size {section.stack_size}.",
            )
            for i, (f, e) in enumerate(zip(found, expected, strict=True))
            if f.shape != e.shape
        ]
    return [
        _problem(
            "slipstream.observation",
            short([s.model_dump() for s in expected], 200),
            short([s.model_dump() for s in found], 200),
            "The observation spec does not match the declared sensors.",
        )
    ]


def check_metadata(
    raw: bytes, policy: bytes, limits: Limits
) -> tuple[CheckedMetadata | None, list[Problem]]:
    """Parse and check ``model_metadata.json`` against the schema, the racing rules and the
    policy bytes. Returns ``(checked, [])`` or ``(None, problems)``; never raises."""
    if len(raw) > limits.max_metadata_bytes:
        found = f"{len(raw)} bytes"
        return None, [
            _problem(
                "(root)",
                f"<= {limits.max_metadata_bytes} bytes",
                found,
                "The metadata file is too big.",
            )
        ]
    try:
        data = _load_json(raw)
    except Exception as exc:
        found = short(f"{type(exc).__name__}: {exc}")
        return None, [
            _problem("(root)", "a UTF-8 JSON object", found, "The file is not valid JSON.")
        ]
    version = _version_problem(data)
    if version:
        return None, [version]
    try:
        meta = ModelMetadata.model_validate(data)
    except ValidationError as exc:
        return None, _from_errors(exc.errors())
    try:
        space = from_deepracer_metadata(
            meta.model_dump(include={"action_space", "action_space_type"})
        )
    except ValidationError as exc:
        return None, _action_space_problems(exc)
    except ValueError as exc:
        return None, [_problem("action_space", "a valid action space", "", str(exc))]
    sensors, problems = _sensors(meta)
    if sensors is None:
        return None, problems
    problems = _consistency(meta, space, sensors, policy)
    if problems:
        return None, problems
    return CheckedMetadata(meta, space, sensors, meta.lidar_config), []


def build_metadata(
    *,
    policy: bytes,
    action_space: ActionSpace,
    sensors: tuple[str, ...],
    neural_network: str,
    training_algorithm: Literal["clipped_ppo", "sac"],
    lidar_config: LidarConfig | None,
    network_preset: str | None,
    training_summary: dict[str, JsonScalar] | None,
    created_at: datetime,
    stack_size: int = 1,
) -> ModelMetadata:
    """The metadata for a policy (raises pydantic's ValidationError on bad values)."""
    discrete = isinstance(action_space, DiscreteActionSpace)
    size = action_space.n if discrete else 2
    convention = DISCRETE_OUTPUT if discrete else CONTINUOUS_OUTPUT
    return ModelMetadata(
        **to_deepracer_metadata(action_space),
        sensor=tuple(DEEPRACER_SENSOR[s] for s in sensors),
        neural_network=neural_network,
        training_algorithm=training_algorithm,
        version=DEEPRACER_VERSION,
        lidar_config=lidar_config,
        slipstream=SlipstreamSection(
            format_version=FORMAT_VERSION,
            observation=stacked_observation_spec(sensors, lidar_config, stack_size),
            output=OutputSpec(convention=convention, size=size),
            network_preset=network_preset,
            stack_size=stack_size,
            training=dict(training_summary or {}),
            created_at=created_at,
            policy_sha256=hashlib.sha256(policy).hexdigest(),
        ),
    )


def dump_metadata(meta: ModelMetadata) -> bytes:
    """Serialise metadata deterministically (sorted keys, two-space indent, UTF-8).

    ``stack_size`` is written only when above 1, so unstacked files are as they were.
    """
    data = meta.model_dump(mode="json")
    if data["slipstream"]["stack_size"] == 1:
        del data["slipstream"]["stack_size"]
    return (json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n").encode()
