"""The one ONNX runner: outputs to actions, and its explicit non-finite rule."""

from __future__ import annotations

import math

import numpy as np
import pytest
from onnx import TensorProto, helper

from submissions import NonFiniteOutput, OnnxRunner
from submissions.onnx_checks import open_session
from submissions.runner import graph_inputs
from tests.submissions.test_support import model

NAN, INF = math.nan, math.inf


def identity(width: int) -> bytes:
    """A graph whose output is its ``lidar`` input: (n, width) float32 -> (n, width)."""
    nodes = [helper.make_node("Identity", ["lidar"], ["out"])]
    inputs = [helper.make_tensor_value_info("lidar", TensorProto.FLOAT, ["n", width])]
    outputs = [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["n", width])]
    return model(nodes, inputs, outputs).SerializeToString()


def runner(width: int, discrete: bool, rule: str, name: str = "policy") -> OnnxRunner:
    return OnnxRunner.from_graph(identity(width), discrete, non_finite=rule, name=name)


def test_finite_outputs_give_the_same_actions_under_both_rules() -> None:
    rng = np.random.default_rng(0)
    for _ in range(5):
        logits = rng.normal(size=4).astype(np.float32)
        for rule in ("zero", "raise"):
            action = runner(4, True, rule).act({"lidar": logits})
            assert isinstance(action, int) and action == int(np.argmax(logits))
        values = rng.normal(scale=2.0, size=2).astype(np.float32)
        for rule in ("zero", "raise"):
            action = runner(2, False, rule).act({"lidar": values})
            assert action.dtype == np.float32
            np.testing.assert_array_equal(action, np.clip(values, -1.0, 1.0))


def test_zero_rule_discrete_never_picks_a_non_finite_logit() -> None:
    policy = runner(3, True, "zero")
    assert policy.act({"lidar": [NAN, 1.0, 2.0]}) == 2
    assert policy.act({"lidar": [-1.0, INF, 0.5]}) == 2
    assert policy.act({"lidar": [NAN, NAN, NAN]}) == 0
    batch = {"lidar": np.array([[NAN, 1.0, 2.0], [3.0, -INF, NAN]], np.float32)}
    np.testing.assert_array_equal(policy.act_batch(batch), [2, 0])


def test_zero_rule_continuous_turns_non_finite_values_into_zero() -> None:
    policy = runner(2, False, "zero")
    np.testing.assert_array_equal(policy.act({"lidar": [NAN, 5.0]}), [0.0, 1.0])
    np.testing.assert_array_equal(policy.act({"lidar": [-INF, -0.5]}), [0.0, -0.5])
    batch = {"lidar": np.array([[INF, 0.25], [-3.0, NAN]], np.float32)}
    np.testing.assert_array_equal(policy.act_batch(batch), [[0.0, 0.25], [-1.0, 0.0]])


@pytest.mark.parametrize(("width", "discrete"), [(3, True), (2, False)])
def test_raise_rule_names_the_driver_and_the_step(width: int, discrete: bool) -> None:
    policy = runner(width, discrete, "raise", name="car entry7")
    policy.act({"lidar": np.zeros(width, np.float32)})
    bad = np.zeros(width, np.float32)
    bad[-1] = NAN
    with pytest.raises(NonFiniteOutput) as caught:
        policy.act({"lidar": bad})
    assert str(caught.value) == "car entry7: the model output NaN or inf at step 2"
    bad[-1] = -INF
    with pytest.raises(NonFiniteOutput, match="at step 3"):
        policy.act_batch({"lidar": np.stack([np.zeros(width, np.float32), bad])})


def test_the_rule_is_explicit() -> None:
    with pytest.raises(ValueError, match="non_finite"):
        runner(3, True, "clip")


def test_graph_inputs_read_dtypes_and_open_dimensions() -> None:
    inputs = [
        helper.make_tensor_value_info("camera", TensorProto.UINT8, ["n", 120, "w", 1]),
        helper.make_tensor_value_info("lidar", TensorProto.FLOAT, ["n", 64]),
    ]
    nodes = [
        helper.make_node("Cast", ["camera"], ["c"], to=TensorProto.FLOAT),
        helper.make_node("ReduceMean", ["c"], ["m"], axes=[1, 2, 3], keepdims=0),
        helper.make_node("ReduceMean", ["lidar"], ["l"], axes=[1], keepdims=0),
        helper.make_node("Add", ["m", "l"], ["out"]),
    ]
    outputs = [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["n"])]
    session = open_session(model(nodes, inputs, outputs).SerializeToString())
    specs = {s.name: (s.shape, s.dtype) for s in graph_inputs(session)}
    assert specs == {"camera": ((120, -1, 1), "uint8"), "lidar": ((64,), "float32")}
