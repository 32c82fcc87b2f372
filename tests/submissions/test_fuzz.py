"""Property tests: mutated archives never make ``validate`` raise.

Runs 500 byte-wise cases on the archive (flip / insert / delete bytes anywhere), 500
byte-wise cases on ``policy.onnx`` alone (repacked with a matching hash, so the bytes
reach the ONNX parser, checker and onnxruntime) and 500 field-wise cases (replace one
metadata value, at any depth, with random JSON): 1500 in all, derandomised, about 15 s
on the 2-core dev machine. Every case must come back as a report that is either ok or
lists problems with every part filled in.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from submissions import ValidationReport, validate
from tests.submissions.test_support import members_of, mlp, pack_bytes, zip_of

VALID = pack_bytes(mlp())
MEMBERS = members_of(VALID)
METADATA = json.loads(MEMBERS["model_metadata.json"])
FUZZ = settings(
    max_examples=500,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def _paths(value: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path (keys and indices) into a JSON value, the root excluded."""
    children = (
        value.items()
        if isinstance(value, dict)
        else enumerate(value)
        if isinstance(value, list)
        else []
    )
    out = []
    for key, child in children:
        out.append((*prefix, key))
        out += _paths(child, (*prefix, key))
    return out


PATHS = _paths(METADATA)
JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=10,
)
MUTATION = st.tuples(
    st.sampled_from(["flip", "insert", "delete"]),
    st.integers(min_value=0, max_value=len(VALID) - 1),
    st.integers(min_value=0, max_value=255),
)


def _check(report: ValidationReport) -> None:
    assert isinstance(report, ValidationReport)
    assert report.ok or all(p.field and p.message and p.expected for p in report.problems)


def _mutate(original: bytes, mutations: list[tuple[str, int, int]]) -> bytes:
    data = bytearray(original)
    for op, position, byte in mutations:
        at = position % (len(data) or 1)
        if op == "flip" and data:
            data[at] ^= byte or 1
        elif op == "insert":
            data.insert(at, byte)
        elif data:
            del data[at]
    return bytes(data)


@FUZZ
@given(st.lists(MUTATION, min_size=1, max_size=8))
def test_archive_byte_mutations_never_raise(mutations: list[tuple[str, int, int]]) -> None:
    _check(validate(_mutate(VALID, mutations)))


@FUZZ
@given(st.lists(MUTATION, min_size=1, max_size=4))
def test_policy_byte_mutations_never_raise(mutations: list[tuple[str, int, int]]) -> None:
    policy = _mutate(MEMBERS["policy.onnx"], mutations)
    data = json.loads(MEMBERS["model_metadata.json"])
    data["slipstream"]["policy_sha256"] = hashlib.sha256(policy).hexdigest()
    _check(validate(zip_of([("model_metadata.json", json.dumps(data)), ("policy.onnx", policy)])))


@FUZZ
@given(st.sampled_from(PATHS), JSON)
def test_field_mutations_never_raise(path: tuple, value: Any) -> None:
    data = json.loads(MEMBERS["model_metadata.json"])
    target = data
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    archive = zip_of(
        [("model_metadata.json", json.dumps(data)), ("policy.onnx", MEMBERS["policy.onnx"])]
    )
    report = validate(archive)
    _check(report)
    if report.ok:
        assert report.info is not None
