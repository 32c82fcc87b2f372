"""Hostile but well-formed uploads for ``hostile_uploads.py``, built in milliseconds.

Each is a valid lidar policy archive (64 beams in, the default discrete action space's
logits out), so it passes the archive, metadata and I/O checks; the bomb and the chain
fold something costly into the output, in constants that onnxruntime folds while it
builds the session. The tests have their own builders (``tests/submissions``), with
variants that hide the sizes from shape inference: benchmarks do not import the tests.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from onnx import TensorProto, helper, numpy_helper

from arena.actions import default_discrete_space
from submissions import pack

BEAMS = 64
SPACE = default_discrete_space()


def _archive(nodes: list, inits: list) -> bytes:
    """The graph ``lidar -> out`` of ``nodes`` packed as a submission's bytes."""
    graph = helper.make_graph(
        nodes,
        "policy",
        [helper.make_tensor_value_info("lidar", TensorProto.FLOAT, ["batch", BEAMS])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["batch", SPACE.n])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    with tempfile.TemporaryDirectory() as tmp:
        path = pack(Path(tmp) / "m.zip", model.SerializeToString(), SPACE, ["lidar"])
        return path.read_bytes()


def _mlp(width: int, seed: int, out: str) -> tuple[list, list]:
    """Nodes and initializers of ``lidar`` -> two ReLU layers of ``width`` -> ``out``."""
    rng = np.random.default_rng(seed)
    weights = {
        "w1": rng.normal(size=(BEAMS, width)) / 8,
        "w2": rng.normal(size=(width, width)) / np.sqrt(width),
        "w3": rng.normal(size=(width, SPACE.n)) / np.sqrt(width),
    }
    inits = [numpy_helper.from_array(w.astype(np.float32), name) for name, w in weights.items()]
    nodes = [
        helper.make_node("MatMul", ["lidar", "w1"], ["h1"]),
        helper.make_node("Relu", ["h1"], ["r1"]),
        helper.make_node("MatMul", ["r1", "w2"], ["h2"]),
        helper.make_node("Relu", ["h2"], ["r2"]),
        helper.make_node("MatMul", ["r2", "w3"], [out]),
    ]
    return nodes, inits


def _with_cost(nodes: list, inits: list, value: str) -> bytes:
    """A small MLP whose logits get ``ReduceMean(value)`` added: an archive's bytes."""
    base_nodes, base_inits = _mlp(16, seed=0, out="logits")
    nodes = [
        *base_nodes,
        *nodes,
        helper.make_node("ReduceMean", [value], ["cost"], keepdims=1),
        helper.make_node("Add", ["logits", "cost"], ["out"]),
    ]
    return _archive(nodes, [*base_inits, *inits])


def wide_mlp(width: int, seed: int = 0) -> bytes:
    """A valid policy with two hidden layers of ``width``: costs about width**2 per step."""
    return _archive(*_mlp(width, seed, out="out"))


def broadcast_bomb(n: int) -> bytes:
    """Constants (n, 1) + (1, n): a few-KB file whose session build fills n * n floats."""
    inits = [
        numpy_helper.from_array(np.ones((n, 1), np.float32), "col"),
        numpy_helper.from_array(np.ones((1, n), np.float32), "row"),
    ]
    return _with_cost([helper.make_node("Add", ["col", "row"], ["square"])], inits, "square")


def matmul_chain(count: int, size: int = 2048) -> bytes:
    """``count`` chained constant size x size MatMuls: count * size**3 multiply-adds to fold."""
    rng = np.random.default_rng(0)
    weight = (rng.normal(size=(size, size)) * 0.5 / np.sqrt(size)).astype(np.float32)
    nodes = [
        helper.make_node("MatMul", ["w" if i == 0 else f"m{i - 1}", "w"], [f"m{i}"])
        for i in range(count)
    ]
    return _with_cost(nodes, [numpy_helper.from_array(weight, "w")], f"m{count - 1}")
