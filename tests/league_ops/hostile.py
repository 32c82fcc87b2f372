"""Valid submissions that turn hostile only on real race observations.

The validator runs models on random lidar readings in [0.15, 1.0); in a race most beams see
nothing within a metre and read exactly 1.0. Each graph below computes a gate that is 1
when the largest reading is 1.0 and 0 otherwise, so it passes validation (fast, finite,
small) and misbehaves once it drives: NaN outputs, a tensor of gigabytes, or seconds of
arithmetic per step. Only allowlisted operators are used.
"""

from __future__ import annotations

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from tests.league.conftest import policy_onnx

N_ACTIONS = 10


def _const(name: str, value: np.ndarray):
    return numpy_helper.from_array(value, name)


def _gated(extra_nodes, extra_inits, penalty: str) -> bytes:
    """The plain lidar MLP whose logits get ``+ penalty`` (a scalar or [1] tensor)."""
    model = onnx.load_from_string(policy_onnx(0))
    graph = model.graph
    graph.node[-1].output[0] = "logits"
    nodes = [
        helper.make_node("ReduceMax", ["lidar"], ["top"], keepdims=0),
        helper.make_node("Sub", ["top", "near_one"], ["over"]),
        helper.make_node("Relu", ["over"], ["pos"]),
        helper.make_node("Mul", ["pos", "huge"], ["scaled"]),
        helper.make_node("Min", ["scaled", "one"], ["gate"]),
        *extra_nodes,
        helper.make_node("Add", ["logits", penalty], ["out"]),
    ]
    graph.node.extend(nodes)
    graph.initializer.extend(
        [
            _const("near_one", np.array(0.9999995, np.float32)),
            _const("huge", np.array(1e7, np.float32)),
            _const("one", np.array(1.0, np.float32)),
            *extra_inits,
        ]
    )
    return model.SerializeToString()


def nan_onnx() -> bytes:
    """Outputs NaN whenever a beam reads 1.0: ``logits + 0 * log(1 - gate)``."""
    nodes = [
        helper.make_node("Sub", ["one", "gate"], ["rest"]),
        helper.make_node("Log", ["rest"], ["log"]),
        helper.make_node("Mul", ["log", "zero"], ["poison"]),
    ]
    return _gated(nodes, [_const("zero", np.array(0.0, np.float32))], "poison")


def _doubled(doublings: int) -> tuple[list, list]:
    """``ones[:1 + 1023 * gate]`` concatenated with itself ``doublings`` times -> "big"."""
    nodes = [
        helper.make_node("Mul", ["gate", "span"], ["extra"]),
        helper.make_node("Add", ["extra", "one"], ["endf"]),
        helper.make_node("Cast", ["endf"], ["end0"], to=TensorProto.INT64),
        helper.make_node("Reshape", ["end0", "shape1"], ["end"]),
        helper.make_node("Slice", ["ones", "start", "end"], ["x0"]),
    ]
    for i in range(doublings):
        nodes.append(helper.make_node("Concat", [f"x{i}", f"x{i}"], [f"x{i + 1}"], axis=0))
    nodes.append(helper.make_node("Identity", [f"x{doublings}"], ["big"]))
    inits = [
        _const("span", np.array(1023.0, np.float32)),
        _const("shape1", np.array([1], np.int64)),
        _const("ones", np.ones(1024, np.float32)),
        _const("start", np.array([0], np.int64)),
    ]
    return nodes, inits


def memory_onnx() -> bytes:
    """Builds a 2**30-float tensor (4 GiB) on race observations, 4 MiB on random ones."""
    nodes, inits = _doubled(20)
    nodes += [
        helper.make_node("ReduceSum", ["big"], ["total"], keepdims=1),
        helper.make_node("Mul", ["total", "zero"], ["nothing"]),
    ]
    return _gated(nodes, [*inits, _const("zero", np.array(0.0, np.float32))], "nothing")


def slow_onnx(passes: int = 300) -> bytes:
    """Runs ``passes`` element-wise ops over 16M floats per step on race observations."""
    nodes, inits = _doubled(14)
    prev = "big"
    for i in range(passes):
        nodes.append(helper.make_node("Sqrt", [prev], [f"s{i}"]))
        prev = f"s{i}"
    nodes += [
        helper.make_node("ReduceSum", [prev], ["total"], keepdims=1),
        helper.make_node("Mul", ["total", "zero"], ["nothing"]),
    ]
    return _gated(nodes, [*inits, _const("zero", np.array(0.0, np.float32))], "nothing")
