"""Hostile but well-formed submissions, built in a few milliseconds (no large files in the repo).

Each is a valid lidar MLP archive (so it passes the archive, metadata and I/O checks) with
something costly folded into its output: the cost hides in constants that onnxruntime
folds while it builds the session. ``hidden=True`` routes the constants' shapes through
``Abs`` and ``Cast`` so static shape inference cannot see the sizes, leaving the cost to the
validation child's limits. ``benchmarks/hostile_uploads.py`` has its own builders
(``benchmarks/hostile_models.py``): benchmarks do not import the tests.
"""

from __future__ import annotations

import numpy as np
import onnx
from onnx import TensorProto, helper

from tests.submissions.test_support import mlp, pack_bytes, tensor


def _hide(name: str, shape: tuple[int, ...], nodes: list, inits: list) -> str:
    """Reshape ``name`` to ``shape`` through ops that shape inference does not follow."""
    inits.append(tensor(f"{name}_shape", np.array(shape, np.float32)))
    nodes += [
        helper.make_node("Abs", [f"{name}_shape"], [f"{name}_abs"]),
        helper.make_node("Cast", [f"{name}_abs"], [f"{name}_dims"], to=TensorProto.INT64),
        helper.make_node("Reshape", [name, f"{name}_dims"], [f"{name}_hidden"]),
    ]
    return f"{name}_hidden"


def _with_constant(nodes: list, inits: list, value: str) -> bytes:
    """The lidar MLP whose logits get ``ReduceMean(value)`` added: an archive's bytes."""
    graph = mlp()
    graph.graph.node[-1].output[0] = "logits"
    nodes += [
        helper.make_node("ReduceMean", [value], ["cost"], keepdims=1),
        helper.make_node("Add", ["logits", "cost"], ["out"]),
    ]
    graph.graph.node.extend(nodes)
    graph.graph.initializer.extend(inits)
    onnx.checker.check_model(graph)
    return pack_bytes(graph)


def broadcast_bomb(n: int, hidden: bool = False) -> bytes:
    """Constants (n, 1) + (1, n): a 1 KB file whose session build fills n * n floats."""
    inits = [tensor("col", np.ones((n, 1), np.float32)), tensor("row", np.ones((1, n), np.float32))]
    nodes: list = []
    col = _hide("col", (n, 1), nodes, inits) if hidden else "col"
    nodes.append(helper.make_node("Add", [col, "row"], ["square"]))
    return _with_constant(nodes, inits, "square")


def matmul_chain(count: int, size: int = 2048, hidden: bool = False) -> bytes:
    """``count`` chained constant size x size MatMuls: count * size**3 multiply-adds to fold."""
    rng = np.random.default_rng(0)
    weight = (rng.normal(size=(size, size)) * 0.5 / np.sqrt(size)).astype(np.float32)
    inits = [tensor("w", weight)]
    nodes: list = []
    w = _hide("w", (size, size), nodes, inits) if hidden else "w"
    last = w
    for i in range(count):
        nodes.append(helper.make_node("MatMul", [last, w], [f"m{i}"]))
        last = f"m{i}"
    return _with_constant(nodes, inits, last)


def wide_mlp(width: int, seed: int = 0) -> bytes:
    """A valid policy with two hidden layers of ``width``: costs about width**2 per step."""
    rng = np.random.default_rng(seed)
    inits = [
        tensor("w1", (rng.normal(size=(64, width)) / 8).astype(np.float32)),
        tensor("w2", (rng.normal(size=(width, width)) / np.sqrt(width)).astype(np.float32)),
        tensor("w3", (rng.normal(size=(width, 10)) / np.sqrt(width)).astype(np.float32)),
    ]
    nodes = [
        helper.make_node("MatMul", ["lidar", "w1"], ["h1"]),
        helper.make_node("Relu", ["h1"], ["r1"]),
        helper.make_node("MatMul", ["r1", "w2"], ["h2"]),
        helper.make_node("Relu", ["h2"], ["r2"]),
        helper.make_node("MatMul", ["r2", "w3"], ["out"]),
    ]
    graph = mlp()
    graph.graph.ClearField("node")
    graph.graph.ClearField("initializer")
    graph.graph.node.extend(nodes)
    graph.graph.initializer.extend(inits)
    return pack_bytes(graph)
