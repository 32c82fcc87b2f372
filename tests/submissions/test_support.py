"""Builders shared by the submission tests: tiny ONNX graphs and raw zip archives.

Graphs are written with ``onnx.helper`` (milliseconds each); the torch-exported
round trips live in ``test_roundtrip.py``. The one test here checks the builders.
"""

from __future__ import annotations

import io
import tempfile
import zipfile
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from arena.actions import ContinuousActionSpace, default_discrete_space
from submissions import pack

CREATED_AT = datetime(2026, 11, 22, 12, 0, tzinfo=UTC)
DISCRETE = default_discrete_space()
CONTINUOUS = ContinuousActionSpace()


def tensor(name: str, array: np.ndarray) -> onnx.TensorProto:
    """An initializer from a numpy array."""
    return numpy_helper.from_array(array, name)


def model(
    nodes: list[onnx.NodeProto],
    inputs: list[onnx.ValueInfoProto],
    outputs: list[onnx.ValueInfoProto],
    initializers: list[onnx.TensorProto] | None = None,
    opset: int = 17,
    **kwargs: Any,
) -> onnx.ModelProto:
    """A model around one graph (IR 8, default-domain opset ``opset``)."""
    graph = helper.make_graph(nodes, "policy", inputs, outputs, initializers or [])
    built = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)], **kwargs)
    built.ir_version = 8
    return built


def mlp(
    n_out: int = 10,
    input_name: str = "lidar",
    n_in: int = 64,
    batch: str | int = "batch",
    seed: int = 0,
) -> onnx.ModelProto:
    """A two-layer MLP: (batch, n_in) float32 -> (batch, n_out) float32."""
    rng = np.random.default_rng(seed)
    inits = [
        tensor("w1", rng.normal(size=(n_in, 16)).astype(np.float32)),
        tensor("b1", np.zeros(16, np.float32)),
        tensor("w2", rng.normal(size=(16, n_out)).astype(np.float32)),
        tensor("b2", np.zeros(n_out, np.float32)),
    ]
    nodes = [
        helper.make_node("Gemm", [input_name, "w1", "b1"], ["h"]),
        helper.make_node("Relu", ["h"], ["r"]),
        helper.make_node("Gemm", ["r", "w2", "b2"], ["out"]),
    ]
    inputs = [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, [batch, n_in])]
    outputs = [helper.make_tensor_value_info("out", TensorProto.FLOAT, [batch, n_out])]
    return model(nodes, inputs, outputs, inits)


def tanh_head(graph_model: onnx.ModelProto) -> onnx.ModelProto:
    """The same model with a Tanh on its output (a continuous policy)."""
    out = graph_model.graph.output[0]
    node = helper.make_node("Tanh", [out.name], ["action"])
    graph_model.graph.node.append(node)
    dims = [d.dim_param or d.dim_value for d in out.type.tensor_type.shape.dim]
    graph_model.graph.ClearField("output")
    graph_model.graph.output.append(
        helper.make_tensor_value_info("action", TensorProto.FLOAT, dims)
    )
    return graph_model


def pack_bytes(
    graph: onnx.ModelProto | bytes, space: Any = DISCRETE, sensors=("lidar",), **kw
) -> bytes:
    """Pack a policy with fixed ``created_at`` and return the archive's bytes."""
    policy = graph if isinstance(graph, bytes) else graph.SerializeToString()
    with tempfile.TemporaryDirectory() as tmp:
        path = pack(Path(tmp) / "m.zip", policy, space, sensors, created_at=CREATED_AT, **kw)
        return path.read_bytes()


def members_of(archive: bytes) -> dict[str, bytes]:
    """The members of a (trusted, test-made) archive."""
    with zipfile.ZipFile(io.BytesIO(archive)) as zf:
        return {name: zf.read(name) for name in zf.namelist()}


def zip_of(members: list[tuple[str | zipfile.ZipInfo, bytes]]) -> bytes:
    """A raw archive with exactly these members, in order (duplicates allowed)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, content in members:
            zf.writestr(name, content)
    return buffer.getvalue()


def test_builders_make_checkable_models() -> None:
    for built in (mlp(), tanh_head(mlp(n_out=2))):
        onnx.checker.check_model(built)
    assert set(members_of(pack_bytes(mlp()))) == {"model_metadata.json", "policy.onnx"}
