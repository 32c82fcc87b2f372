"""``stack_size`` in the model file: stacked input shapes, their checks, and racing them."""

from __future__ import annotations

import json

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper

from arena.config import CarConfig, RaceConfig
from arena.race import run_race
from league.jobs.evaluation import model_car
from submissions import load_policy, validate
from submissions.preflight import preflight
from tests.submissions.test_support import (
    DISCRETE,
    members_of,
    mlp,
    model,
    pack_bytes,
    tensor,
    zip_of,
)


def camera_graph(frames: int, n_out: int = DISCRETE.n) -> onnx.ModelProto:
    """uint8 (batch, 120, 160, frames) -> mean of each channel -> Gemm -> (batch, n_out)."""
    rng = np.random.default_rng(frames)
    nodes = [
        helper.make_node("Cast", ["camera"], ["f"], to=TensorProto.FLOAT),
        helper.make_node("ReduceMean", ["f"], ["m"], axes=[1, 2], keepdims=0),
        helper.make_node("Gemm", ["m", "w", "b"], ["logits"]),
    ]
    inits = [
        tensor("w", rng.normal(size=(frames, n_out)).astype(np.float32)),
        tensor("b", np.zeros(n_out, np.float32)),
    ]
    dims = ["batch", 120, 160, frames]
    inputs = [helper.make_tensor_value_info("camera", TensorProto.UINT8, dims)]
    outputs = [helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["batch", n_out])]
    return model(nodes, inputs, outputs, inits)


def with_metadata(archive: bytes, edit) -> bytes:
    """The archive with its metadata JSON passed through ``edit`` (a dict -> None)."""
    members = members_of(archive)
    meta = json.loads(members["model_metadata.json"])
    edit(meta)
    members["model_metadata.json"] = json.dumps(meta).encode()
    return zip_of(list(members.items()))


@pytest.fixture(scope="module")
def stacked_zip() -> bytes:
    return pack_bytes(camera_graph(3), sensors=("camera",), stack_size=3)


def test_a_stacked_camera_graph_validates_with_its_stack_size(stacked_zip: bytes) -> None:
    report = validate(stacked_zip)
    assert report.ok, report.problems
    assert report.info is not None and report.info.stack_size == 3
    assert report.info.observation[0].shape == (120, 160, 3)
    meta = json.loads(members_of(stacked_zip)["model_metadata.json"])
    assert meta["slipstream"]["stack_size"] == 3


def test_an_unstacked_file_has_no_key_and_reads_as_1() -> None:
    archive = pack_bytes(mlp())
    assert "stack_size" not in json.loads(members_of(archive)["model_metadata.json"])["slipstream"]
    report = validate(archive)
    assert report.ok and report.info is not None and report.info.stack_size == 1
    stacked_lidar = pack_bytes(mlp(n_in=192), stack_size=3)
    report = validate(stacked_lidar)
    assert report.ok, report.problems
    assert report.info is not None and report.info.observation[0].shape == (192,)


@pytest.mark.parametrize(
    ("frames", "declared", "expected", "found"),
    [(1, 3, "(batch, 120, 160, 3)", "160, 1]"), (3, 1, "(batch, 120, 160, 1)", "160, 3]")],
)
def test_a_graph_that_does_not_match_the_stack_size_is_refused(
    frames: int, declared: int, expected: str, found: str
) -> None:
    archive = pack_bytes(camera_graph(frames), sensors=("camera",), stack_size=declared)
    report = validate(archive)
    assert not report.ok
    (problem,) = report.problems
    assert problem.field == "policy.onnx:input:camera"
    assert expected in problem.expected and found in problem.found
    assert f"stack_size {declared}" in problem.message
    assert f"reads {frames} frame(s)" in problem.message


def test_an_observation_spec_of_the_wrong_stack_is_refused(stacked_zip: bytes) -> None:
    def unstack(meta: dict) -> None:
        meta["slipstream"]["observation"][0]["shape"] = [120, 160, 1]

    report = validate(with_metadata(stacked_zip, unstack))
    (problem,) = report.problems
    assert problem.field == "model_metadata.json:slipstream.observation[0].shape"
    assert problem.expected == "(120, 160, 3)" and problem.found == "(120, 160, 1)"
    assert "stack_size 3" in problem.message


@pytest.mark.parametrize("bad", [0, 9])
def test_stack_size_outside_1_to_8_is_refused(stacked_zip: bytes, bad: int) -> None:
    def set_bad(meta: dict) -> None:
        meta["slipstream"]["stack_size"] = bad

    report = validate(with_metadata(stacked_zip, set_bad))
    assert [p.field for p in report.problems] == ["model_metadata.json:slipstream.stack_size"]
    with pytest.raises(ValueError, match="stack_size"):
        pack_bytes(camera_graph(3), sensors=("camera",), stack_size=bad)


def test_a_stacked_model_races_with_stacked_observations(stacked_zip: bytes) -> None:
    policy = load_policy(stacked_zip)
    car = model_car("entry1", policy.info.model_dump(mode="json"))
    assert car.stack_size == 3
    assert model_car("entry2", {"sensors": ["lidar"], "action_space": DISCRETE}).stack_size == 1
    config = RaceConfig.build(cars=[car], laps=1, time_limit_s=3.0)
    result = run_race(config, {"entry1": policy})
    assert policy.runs == len(result.trace["entry1"]["status"]) > 10
    config = RaceConfig.build(
        cars=[CarConfig(name="m", sensors=("camera",), action_space=DISCRETE)], time_limit_s=1.0
    )
    with pytest.raises(ValueError):  # one frame is not what the graph reads
        run_race(config, {"m": load_policy(stacked_zip)})
    assert preflight(stacked_zip, "beginner_loop", time_limit_s=2.0).status == "time_up"
