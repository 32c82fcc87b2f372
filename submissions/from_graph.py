"""Derive a submission's ``slipstream`` section from an ONNX graph trained elsewhere.

A policy exported by any trainer says what it reads (its inputs' names, dtypes and
shapes) and how wide its output is; the racer's DeepRacer ``model_metadata.json`` says
which sensors and action space it should have. :func:`derive_section` checks the two
against each other and fills the section (observation, output, stack size, policy hash),
or raises :class:`GraphSpecError` with every mismatch as a plain sentence. The graph is
only parsed as protobuf data, never run; :func:`submissions.validate` does the rest.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import onnx

from arena.actions import DiscreteActionSpace
from arena.sensors_spec import DEEPRACER_SENSOR, MAX_STACK_SIZE, LidarConfig, check_sensors
from submissions.format import (
    CONTINUOUS_OUTPUT,
    DISCRETE_OUTPUT,
    InputSpec,
    observation_spec,
    short,
)
from submissions.metadata import ActionSpace, OutputSpec, stacked_observation_spec


class GraphSpecError(ValueError):
    """The graph does not fit the metadata; ``problems`` holds one sentence per mismatch."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__(" ".join(problems))
        self.problems = problems


@dataclass(frozen=True)
class GraphSection:
    """What the graph fills in: the ``slipstream`` section's graph-derived fields."""

    observation: tuple[InputSpec, ...]
    output: OutputSpec
    stack_size: int
    policy_sha256: str
    network_preset: None = None


def _dtype(value: onnx.ValueInfoProto) -> str:
    elem = value.type.tensor_type.elem_type
    if not elem:
        return "an unknown type"
    return str(onnx.helper.tensor_dtype_to_np_dtype(elem))


def _dims(value: onnx.ValueInfoProto) -> list[int | str] | None:
    tensor = value.type.tensor_type
    if not value.type.HasField("tensor_type") or not tensor.HasField("shape"):
        return None
    return [
        d.dim_value if d.HasField("dim_value") else (d.dim_param or "?") for d in tensor.shape.dim
    ]


def _shape_text(shape: tuple[int, ...] | list[int | str]) -> str:
    return "(batch, " + ", ".join(map(str, shape)) + ")"


def _stack(dims: list[int | str], frame: InputSpec) -> int | None:
    """The frames stacked in an input of ``dims`` (batch excluded), or None if it cannot be."""
    if len(dims) != len(frame.shape) or list(dims[:-1]) != list(frame.shape[:-1]):
        return None
    last = dims[-1]
    if not isinstance(last, int) or last % frame.shape[-1]:
        return None
    k = last // frame.shape[-1]
    return k if 1 <= k <= MAX_STACK_SIZE else None


def _input_problems(value: onnx.ValueInfoProto, frame: InputSpec) -> tuple[int | None, list[str]]:
    """The stack size of one input and its problems."""
    name = frame.name
    problems = []
    if _dtype(value) != frame.dtype:
        problems.append(
            f"Input '{name}' is {_dtype(value)}, but a {name} input must be {frame.dtype}."
        )
    dims = _dims(value)
    if dims is None:
        return None, [
            *problems,
            f"Input '{name}' has no declared shape; it must be {_shape_text(frame.shape)}.",
        ]
    if not dims or not (isinstance(dims[0], str) or dims[0] == 1):
        problems.append(
            f"Input '{name}' has shape {short(dims)}: its first dimension is the batch and must "
            "be dynamic (symbolic) or 1."
        )
        return None, problems
    k = _stack(dims[1:], frame)
    if k is None:
        stacked = (*frame.shape[:-1], f"{frame.shape[-1]}k")
        problems.append(
            f"Input '{name}' has shape {_shape_text(dims[1:])}, but a {name} input has shape "
            f"{_shape_text(frame.shape)}, or {_shape_text(stacked)} for k stacked frames "
            f"(k 1-{MAX_STACK_SIZE})."
        )
    return k, problems


def _output_problems(model: onnx.ModelProto, space: ActionSpace) -> list[str]:
    discrete = isinstance(space, DiscreteActionSpace)
    size = space.n if discrete else 2
    want = (
        f"the action space in model_metadata.json has {size} discrete actions, so the graph "
        f"must output {size} logits per step"
        if discrete
        else "the action space in model_metadata.json is continuous, so the graph must "
        "output 2 values per step (steering, speed, in [-1, 1])"
    )
    outputs = model.graph.output
    if len(outputs) != 1:
        names = short([o.name for o in outputs])
        return [f"The graph has {len(outputs)} outputs {names}; it must have exactly one: {want}."]
    out = outputs[0]
    problems = []
    if _dtype(out) != "float32":
        problems.append(f"Output '{short(out.name)}' is {_dtype(out)}; it must be float32.")
    dims = _dims(out)
    if dims is None or len(dims) != 2 or not isinstance(dims[1], int):
        problems.append(
            f"Output '{short(out.name)}' has shape {short(dims)}; it must be "
            f"(batch, {size}): {want}."
        )
    elif dims[1] != size:
        problems.append(f"The graph outputs {dims[1]} values per step, but {want}.")
    return problems


def derive_section(
    policy: bytes,
    action_space: ActionSpace,
    sensors: tuple[str, ...] | list[str],
    lidar_config: LidarConfig | None = None,
) -> GraphSection:
    """Fill the ``slipstream`` section's graph fields from ``policy`` (ONNX bytes) and the
    metadata's action space and sensors (Slipstream names); raises :class:`GraphSpecError`.
    """
    sensors = check_sensors(sensors)
    try:
        model = onnx.load_model_from_string(policy)
    except Exception as exc:
        raise GraphSpecError([f"The file is not an ONNX model ({short(str(exc))})."]) from None
    initializers = {t.name for t in model.graph.initializer}
    inputs = {v.name: v for v in model.graph.input if v.name not in initializers}
    problems = []
    if sorted(inputs) != sorted(sensors):
        declared = [DEEPRACER_SENSOR[s] for s in sensors]
        problems.append(
            f"The graph's inputs are named {short(list(inputs))}, but for the sensors {declared} "
            f"in model_metadata.json they must be named {list(sensors)}: one input per sensor, "
            "named after it (torch.onnx.export's input_names)."
        )
    frames = {s.name: s for s in observation_spec(sensors, lidar_config)}
    stacks: dict[str, int] = {}
    for name, frame in frames.items():
        if name in inputs:
            k, found = _input_problems(inputs[name], frame)
            problems += found
            if k is not None:
                stacks[name] = k
    if len(set(stacks.values())) > 1:
        problems.append(
            f"The inputs stack different numbers of frames ({stacks}); all sensors must stack "
            "the same number."
        )
    problems += _output_problems(model, action_space)
    if problems:
        raise GraphSpecError(problems)
    k = next(iter(stacks.values()))
    discrete = isinstance(action_space, DiscreteActionSpace)
    return GraphSection(
        observation=stacked_observation_spec(sensors, lidar_config, k),
        output=OutputSpec(
            convention=DISCRETE_OUTPUT if discrete else CONTINUOUS_OUTPUT,
            size=action_space.n if discrete else 2,
        ),
        stack_size=k,
        policy_sha256=hashlib.sha256(policy).hexdigest(),
    )
