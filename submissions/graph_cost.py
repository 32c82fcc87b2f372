"""The static cost of one batch-1 step of a policy graph: bytes its nodes compute, multiply-adds.

Shapes come from ONNX shape inference with data propagation, without running anything.
Symbolic dimensions count as 1 (the batch); a value whose shape inference cannot know is
not counted. So this is a floor, cheap enough to refuse the obvious bombs before
onnxruntime folds them; what it cannot see is caught by the limits of the process that
builds the session (``league.http.upload_validation``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import onnx
from onnx import shape_inference

UNKNOWN_ITEM_BYTES = 8


@dataclass(frozen=True)
class Value:
    """One tensor the graph computes, with its batch-1 shape and size."""

    name: str
    dims: tuple[int, ...]
    bytes: int


@dataclass(frozen=True)
class GraphCost:
    """What one batch-1 step computes: all node outputs' bytes, the largest, multiply-adds."""

    computed_bytes: int = 0
    largest: Value | None = None
    macs: int = 0


def _dims(value: onnx.ValueInfoProto) -> tuple[int, ...] | None:
    tensor = value.type.tensor_type
    if not value.type.HasField("tensor_type") or not tensor.HasField("shape"):
        return None
    return tuple(max(d.dim_value, 1) if d.HasField("dim_value") else 1 for d in tensor.shape.dim)


def _item_bytes(elem_type: int) -> int:
    try:
        return onnx.helper.tensor_dtype_to_np_dtype(elem_type).itemsize
    except (KeyError, TypeError, ValueError):
        return UNKNOWN_ITEM_BYTES


def _macs(node: onnx.NodeProto, shapes: dict[str, tuple[int, ...]]) -> int:
    """Multiply-adds of a MatMul, Gemm or Conv whose shapes are known; 0 otherwise."""
    if not node.input or not node.output:
        return 0
    out, first = shapes.get(node.output[0]), shapes.get(node.input[0])
    second = shapes.get(node.input[1]) if len(node.input) > 1 else None
    if out is None or first is None or second is None:
        return 0
    if node.op_type == "MatMul" and first:
        return math.prod(out) * first[-1]
    if node.op_type == "Gemm" and len(first) == 2:
        trans_a = any(a.name == "transA" and a.i for a in node.attribute)
        return math.prod(out) * first[0 if trans_a else 1]
    if node.op_type == "Conv" and len(second) > 1:
        return math.prod(out) * math.prod(second[1:])
    return 0


def graph_cost(model: onnx.ModelProto) -> GraphCost:
    """The static cost of one batch-1 step; an empty cost if shape inference fails."""
    try:
        inferred = shape_inference.infer_shapes(model, strict_mode=False, data_prop=True)
    except Exception:  # a graph inference cannot follow: left to the child's limits
        return GraphCost()
    graph = inferred.graph
    shapes = {t.name: tuple(max(int(d), 1) for d in t.dims) for t in graph.initializer}
    types: dict[str, int] = {}
    for value in [*graph.input, *graph.value_info, *graph.output]:
        dims = _dims(value)
        if dims is not None:
            shapes[value.name] = dims
            types[value.name] = value.type.tensor_type.elem_type
    total, largest, macs = 0, None, 0
    for node in graph.node:
        macs += _macs(node, shapes)
        for name in node.output:
            if name not in shapes:
                continue
            size = math.prod(shapes[name]) * _item_bytes(types.get(name, 0))
            total += size
            if largest is None or size > largest.bytes:
                largest = Value(name, shapes[name], size)
    return GraphCost(computed_bytes=total, largest=largest, macs=macs)
