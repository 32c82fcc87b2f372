"""Hostile and broken submissions: each gets its own clear Problem, nothing escapes."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import warnings
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from onnx import TensorProto, helper

from submissions import Limits, Problem, ValidationReport, validate
from submissions.archive import read_archive
from submissions.onnx_checks import ALLOWED_OPS
from tests.submissions.hostile_models import wide_mlp
from tests.submissions.test_support import (
    CONTINUOUS,
    DISCRETE,
    members_of,
    mlp,
    model,
    pack_bytes,
    tanh_head,
    tensor,
    zip_of,
)

VALID = pack_bytes(mlp())
MEMBERS = members_of(VALID)
METADATA = json.loads(MEMBERS["model_metadata.json"])
DEFAULT = Limits()


def refused(source, limits: Limits = DEFAULT) -> Problem:
    """Validate, assert refusal, and return the first problem (after sanity checks)."""
    report = validate(source, limits)
    assert isinstance(report, ValidationReport)
    assert not report.ok
    for p in report.problems:
        assert p.field and p.message and p.expected and p.found is not None
    return report.problems[0]


def with_metadata(change) -> bytes:
    """The valid archive with its metadata dict edited by ``change``."""
    data = json.loads(MEMBERS["model_metadata.json"])
    change(data)
    return zip_of(
        [("model_metadata.json", json.dumps(data)), ("policy.onnx", MEMBERS["policy.onnx"])]
    )


def with_graph(graph, space=DISCRETE, sensors=("lidar",)) -> bytes:
    return pack_bytes(graph, space, sensors)


def test_valid_archive_passes() -> None:
    report = validate(VALID)
    assert report.ok, report.problems
    assert report.info is not None and report.info.latency_ms is not None


# --- archive ---------------------------------------------------------------------------


def test_random_bytes() -> None:
    p = refused(os.urandom(4096))
    assert p.field == "archive" and "not a readable zip" in p.message


def test_empty_bytes_and_empty_file(tmp_path: Path) -> None:
    assert "empty" in refused(b"").message
    (tmp_path / "empty.zip").write_bytes(b"")
    assert "empty" in refused(tmp_path / "empty.zip").message


def test_missing_file(tmp_path: Path) -> None:
    assert "could not be read" in refused(tmp_path / "nope.zip").message


def test_truncated_zip() -> None:
    assert refused(VALID[: len(VALID) // 2]).field == "archive"


def test_corrupted_member_data() -> None:
    with zipfile.ZipFile(__import__("io").BytesIO(VALID)) as zf:
        info = zf.getinfo("policy.onnx")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    data = bytearray(VALID)
    for i in range(start + 10, start + 40):
        data[i] ^= 0xFF
    p = refused(bytes(data))
    assert p.field == "archive:policy.onnx" and "could not be decompressed" in p.message


def test_archive_over_size_cap() -> None:
    p = refused(VALID, Limits(max_archive_bytes=100))
    assert p.field == "archive" and "upload limit" in p.message


def test_zip_bomb_declared_size() -> None:
    bomb = zip_of([("model_metadata.json", b"{}"), ("policy.onnx", bytes(130 * 1024 * 1024))])
    assert len(bomb) < 1024 * 1024
    problems = validate(bomb).problems
    assert problems[0].field == "archive:policy.onnx"
    assert any("zip bomb" in p.message for p in problems)


def _patch_headers(
    data: bytearray, name: bytes, local_offset: int, central_offset: int, fmt: str, value: int
) -> None:
    """Overwrite one field in both the local and the central header of member ``name``."""
    for signature, offset, name_len_at, name_at in (
        (b"PK\x03\x04", local_offset, 26, 30),
        (b"PK\x01\x02", central_offset, 28, 46),
    ):
        at = data.find(signature)
        while at != -1:
            length = struct.unpack_from("<H", data, at + name_len_at)[0]
            if data[at + name_at : at + name_at + length] == name:
                struct.pack_into(fmt, data, at + offset, value)
            at = data.find(signature, at + 4)


def test_zip_bomb_lying_header() -> None:
    """Headers claim 1000 bytes; the stream holds 3 MB of zeros. Reading stops at the
    declared size, so the lie shows as a CRC mismatch; with the CRC patched to match, the
    member is its first 1000 bytes: nothing past the declared size is ever inflated."""
    data = bytearray(zip_of([("model_metadata.json", b"{}"), ("policy.onnx", bytes(3 << 20))]))
    _patch_headers(data, b"policy.onnx", 22, 24, "<I", 1000)
    p = refused(bytes(data))
    assert p.field == "archive:policy.onnx" and "could not be decompressed" in p.message
    assert "CRC" in p.found
    _patch_headers(data, b"policy.onnx", 14, 16, "<I", zlib.crc32(bytes(1000)))
    members, problems = read_archive(bytes(data), DEFAULT)
    assert members is not None and members["policy.onnx"] == bytes(1000), problems


def test_total_uncompressed_cap() -> None:
    """Members each within their own cap but over the total together: refused on the
    declared sizes; exactly the total passes."""
    total = sum(len(content) for content in MEMBERS.values())
    p = refused(VALID, Limits(max_total_uncompressed_bytes=total - 1))
    assert p.field == "archive" and "expands to more than the format allows" in p.message
    assert f"at most {total - 1} bytes" in p.expected and f"{total} bytes" in p.found
    assert validate(VALID, Limits(max_total_uncompressed_bytes=total)).ok


def test_member_count_cap() -> None:
    p = refused(zip_of([(f"f{i}", b"") for i in range(20)]))
    assert "too many members" in p.message


@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("../policy.onnx", "traversal"),
        ("a/../../x", "traversal"),
        ("/etc/passwd", "Absolute"),
        ("C:/evil.onnx", "Absolute"),
        ("evil.py", "does not allow"),
        ("policy.onnx/", "does not allow"),
    ],
)
def test_bad_member_names(name: str, words: str) -> None:
    p = refused(zip_of([*MEMBERS.items(), (name, b"x")]))
    assert p.field.startswith("archive:") and words in p.message


def test_symlink_member() -> None:
    link = zipfile.ZipInfo("reward_function.py")
    link.external_attr = 0o120777 << 16
    p = refused(zip_of([*MEMBERS.items(), (link, b"/etc/passwd")]))
    assert "Symlink" in p.message


def test_encrypted_member() -> None:
    data = bytearray(zip_of([*MEMBERS.items(), ("metrics.csv", b"a,b\n")]))
    _patch_headers(data, b"metrics.csv", 6, 8, "<H", 0x1)
    p = refused(bytes(data))
    assert "Encrypted" in p.message


def test_duplicate_member() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        archive = zip_of([*MEMBERS.items(), ("policy.onnx", b"other")])
    assert "more than once" in refused(archive).message


def test_missing_policy() -> None:
    p = refused(zip_of([("model_metadata.json", MEMBERS["model_metadata.json"])]))
    assert "lacks the required member policy.onnx" in p.message


def test_oversized_metadata() -> None:
    big = json.dumps({**METADATA, "pad": "x" * 100_000})
    p = refused(zip_of([("model_metadata.json", big), ("policy.onnx", MEMBERS["policy.onnx"])]))
    assert p.field == "archive:model_metadata.json" and "larger" in p.message


# --- metadata --------------------------------------------------------------------------


def test_not_json() -> None:
    p = refused(zip_of([("model_metadata.json", b"{nope"), ("policy.onnx", b"")]))
    assert p.field == "model_metadata.json:(root)" and "not valid JSON" in p.message


@pytest.mark.parametrize("text", ['{"a": NaN}', '{"a": 1, "a": 2}', "[1, 2]", '"x"', "\xff"])
def test_odd_json(text: str) -> None:
    archive = zip_of([("model_metadata.json", text.encode("latin-1")), ("policy.onnx", b"")])
    assert refused(archive).field.startswith("model_metadata.json:")


def test_wrong_json_types() -> None:
    def change(d):
        d["sensor"] = "LIDAR"
        d["slipstream"]["output"]["size"] = "ten"

    fields = {p.field for p in validate(with_metadata(change)).problems}
    assert fields == {"model_metadata.json:sensor", "model_metadata.json:slipstream.output.size"}


def test_missing_and_extra_keys() -> None:
    def change(d):
        del d["neural_network"]
        d["surprise"] = 1

    report = validate(with_metadata(change))
    found = {(p.field, p.expected) for p in report.problems}
    assert ("model_metadata.json:neural_network", "a value") in found
    assert ("model_metadata.json:surprise", "no such key") in found


def test_unknown_sensor() -> None:
    p = refused(with_metadata(lambda d: d.update(sensor=["LIDAR", "RADAR"])))
    assert p.field == "model_metadata.json:sensor[1]" and "Unknown sensor" in p.message


def test_two_cameras() -> None:
    p = refused(with_metadata(lambda d: d.update(sensor=["FRONT_FACING_CAMERA", "STEREO_CAMERAS"])))
    assert p.field == "model_metadata.json:sensor" and "camera" in p.message


def test_speed_above_limit() -> None:
    p = refused(with_metadata(lambda d: d["action_space"][2].update(speed=4.5)))
    assert p.field == "model_metadata.json:action_space[2].speed"
    assert p.expected == "<= 4.0" and p.found == "4.5"


def test_continuous_low_not_below_high() -> None:
    archive = pack_bytes(tanh_head(mlp(n_out=2)), CONTINUOUS)
    members = members_of(archive)
    data = json.loads(members["model_metadata.json"])
    data["action_space"]["speed"] = {"low": 2.0, "high": 2.0}
    bad = zip_of(
        [("model_metadata.json", json.dumps(data)), ("policy.onnx", members["policy.onnx"])]
    )
    p = refused(bad)
    assert p.field == "model_metadata.json:action_space.speed" and "below high" in p.message


def test_unsupported_format_version() -> None:
    p = refused(with_metadata(lambda d: d["slipstream"].update(format_version=2, other="x")))
    assert p.field == "model_metadata.json:slipstream.format_version"


def test_observation_mismatch() -> None:
    p = refused(with_metadata(lambda d: d["slipstream"]["observation"][0].update(shape=[32])))
    assert p.field == "model_metadata.json:slipstream.observation[0].shape"
    assert (p.expected, p.found) == ("(64,)", "(32,)")
    p = refused(with_metadata(lambda d: d["slipstream"]["observation"][0].update(name="camera")))
    assert p.field == "model_metadata.json:slipstream.observation"


def test_output_mismatch() -> None:
    p = refused(with_metadata(lambda d: d["slipstream"]["output"].update(size=9)))
    assert p.field == "model_metadata.json:slipstream.output"


def test_policy_hash_mismatch() -> None:
    archive = zip_of(
        [("model_metadata.json", MEMBERS["model_metadata.json"]), ("policy.onnx", b"\x08\x08")]
    )
    assert refused(archive).field == "model_metadata.json:slipstream.policy_sha256"


def test_sac_with_discrete_space() -> None:
    p = refused(with_metadata(lambda d: d.update(training_algorithm="sac")))
    assert p.field == "model_metadata.json:training_algorithm"


# --- ONNX graph ------------------------------------------------------------------------


def _lidar_io(n_out: int = 10):
    return (
        [helper.make_tensor_value_info("lidar", TensorProto.FLOAT, ["batch", 64])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["batch", n_out])],
    )


def _mlp_with(node, extra_inits=(), opset: int = 17, **kw):
    """The MLP, with ``node`` mapping its output ``out`` to ``out2`` appended."""
    base = mlp()
    base.graph.node.append(node)
    base.graph.initializer.extend(extra_inits)
    base.graph.output[0].name = "out2"
    graph = model(list(base.graph.node), list(base.graph.input), list(base.graph.output),
                  list(base.graph.initializer), opset=opset, **kw)  # fmt: skip
    return graph


def test_not_onnx() -> None:
    p = refused(with_graph(b"\xff\xff\xff\xff not a protobuf"))
    assert p.field == "policy.onnx"


def test_custom_domain_op() -> None:
    node = helper.make_node("Exec", ["out"], ["out2"], domain="com.evil")
    graph = _mlp_with(node)
    graph.opset_import.append(helper.make_opsetid("com.evil", 1))
    p = refused(with_graph(graph))
    assert p.field == "policy.onnx:node[3]" and p.found == "com.evil:Exec"


def test_disallowed_op() -> None:
    assert "RandomNormalLike" not in ALLOWED_OPS
    p = refused(with_graph(_mlp_with(helper.make_node("RandomNormalLike", ["out"], ["out2"]))))
    assert p.field == "policy.onnx:node[3]" and "allowlist" in p.message


def test_loop_with_subgraph() -> None:
    body = helper.make_graph(
        [helper.make_node("Identity", ["cond_in"], ["cond_out"]),
         helper.make_node("Identity", ["x_in"], ["x_out"])],
        "body",
        [helper.make_tensor_value_info("i", TensorProto.INT64, []),
         helper.make_tensor_value_info("cond_in", TensorProto.BOOL, []),
         helper.make_tensor_value_info("x_in", TensorProto.FLOAT, None)],
        [helper.make_tensor_value_info("cond_out", TensorProto.BOOL, []),
         helper.make_tensor_value_info("x_out", TensorProto.FLOAT, None)],
    )  # fmt: skip
    inits = [tensor("trip", np.array(2, np.int64)), tensor("cond", np.array(True))]
    node = helper.make_node("Loop", ["trip", "cond", "out"], ["out2"], body=body)
    report = validate(with_graph(_mlp_with(node, inits)))
    messages = {p.message for p in report.problems}
    assert {
        "The operator is not on the allowlist.",
        "Subgraphs (control flow) are refused.",
    } <= messages


def test_model_functions() -> None:
    fn = helper.make_function("local", "Twice", ["x"], ["y"],
                              [helper.make_node("Add", ["x", "x"], ["y"])],
                              [helper.make_opsetid("", 17)])  # fmt: skip
    node = helper.make_node("Twice", ["out"], ["out2"], domain="local")
    graph = _mlp_with(node, functions=[fn])
    graph.opset_import.append(helper.make_opsetid("local", 1))
    fields = {p.field for p in validate(with_graph(graph)).problems}
    assert {"policy.onnx:functions", "policy.onnx:node[3]"} <= fields


def test_external_data_tensor() -> None:
    graph = mlp()
    w1 = graph.graph.initializer[0]
    w1.ClearField("raw_data")
    w1.data_location = TensorProto.EXTERNAL
    w1.external_data.add(key="location", value="../../../etc/passwd")
    p = refused(with_graph(graph))
    assert p.field == "policy.onnx:initializer[0]" and "external data" in p.message


@pytest.mark.parametrize("opset", [11, 22])
def test_opset_out_of_range(opset: int) -> None:
    graph = mlp()
    graph.opset_import[0].version = opset
    p = refused(with_graph(graph))
    assert p.field == "policy.onnx:opset_import" and p.found == str(opset)


def test_wrong_input_name() -> None:
    p = refused(with_graph(mlp(input_name="lidar_scan")))
    assert p.field == "policy.onnx:graph.input" and "lidar_scan" in p.found


def test_wrong_input_shape() -> None:
    graph = mlp(n_in=32)
    meta = with_metadata(lambda d: None)
    assert validate(meta).ok
    p = refused(with_graph(graph))
    assert p.field == "policy.onnx:input:lidar" and "shape does not match" in p.message


def test_fixed_batch_other_than_one() -> None:
    p = refused(with_graph(mlp(batch=4)))
    assert p.field == "policy.onnx:input:lidar"


def test_camera_input_must_be_uint8() -> None:
    inputs = [helper.make_tensor_value_info("camera", TensorProto.FLOAT, ["b", 120, 160, 1])]
    outputs = [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["b", 10])]
    node = helper.make_node("ReduceMean", ["camera"], ["m"], axes=[2, 3], keepdims=0)
    tile = helper.make_node("Gemm", ["m", "w", "bias"], ["y"])
    inits = [tensor("w", np.ones((120, 10), np.float32)), tensor("bias", np.zeros(10, np.float32))]
    graph = model([node, tile], inputs, outputs, inits)
    p = refused(with_graph(graph, sensors=("camera",)))
    assert p.field == "policy.onnx:input:camera" and "uint8" in p.expected


def test_wrong_output_size() -> None:
    p = refused(with_graph(mlp(n_out=5)))
    assert p.field == "policy.onnx:output:out" and p.expected == "float32 (batch, 10)"


def test_two_outputs() -> None:
    graph = mlp()
    graph.graph.output.append(helper.make_tensor_value_info("h", TensorProto.FLOAT, ["batch", 16]))
    assert refused(with_graph(graph)).field == "policy.onnx:graph.output"


def test_too_many_parameters() -> None:
    p = refused(with_graph(mlp()), Limits(max_parameters=100))
    assert p.field == "policy.onnx:graph" and "weights" in p.message


def test_nan_outputs() -> None:
    zero = tensor("zero", np.zeros(1, np.float32))
    graph = _mlp_with(helper.make_node("Div", ["out", "zero"], ["q"]), [zero])
    graph.graph.node.append(helper.make_node("Sub", ["q", "q"], ["out2"]))
    graph.graph.node[3].output[0] = "q"
    p = refused(with_graph(graph))
    assert p.field == "policy.onnx:run" and "NaN" in p.message


def test_too_slow() -> None:
    report = validate(VALID, Limits(max_latency_ms=1e-6))
    assert [p.field for p in report.problems] == ["policy.onnx:latency"]
    assert "ms of CPU time per step" in report.problems[0].expected
    assert report.info is not None and report.info.latency_ms > 0


@contextmanager
def busy_cpu(hogs: int) -> Iterator[None]:
    """This process and ``hogs`` busy-looping processes, all pinned to one CPU."""
    mine = os.sched_getaffinity(0)
    cpu = {min(mine)}
    loops = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(hogs)]
    try:
        for loop in loops:
            os.sched_setaffinity(loop.pid, cpu)
        os.sched_setaffinity(0, cpu)
        yield
    finally:
        os.sched_setaffinity(0, mine)
        for loop in loops:
            loop.kill()
            loop.wait()


def test_speed_verdict_survives_a_busy_machine() -> None:
    """A policy well inside the limit stays inside while three processes share its CPU.

    Wall time under this load was about 10x the unloaded figure; CPU time stays within
    about 3x (caches and frequency still move it), so a 4x limit tells the two apart.
    """
    policy = wide_mlp(2048)
    alone = validate(policy).info.latency_ms
    limits = Limits(max_latency_ms=4 * alone)
    with busy_cpu(hogs=3):
        report = validate(policy, limits)
    assert report.ok, (alone, report.problems)


def test_run_without_policy_skips_behaviour() -> None:
    report = validate(VALID, run_policy=False)
    assert report.ok and report.info is not None and report.info.latency_ms is None
