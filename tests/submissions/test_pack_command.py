"""``slipstream model pack``: the documented example (trained, exported, packed, raced), the
RUN form, and graphs that do not fit their metadata (exit 2, no file written)."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import onnx
import pytest
from onnx import TensorProto, helper
from typer.testing import CliRunner

from agents.action_spaces import parse_action_space_spec
from agents.hyperparameters import Hyperparameters
from agents.settings import TrainSettings
from agents.train import Trainer
from arena import make_config
from arena.actions import parse_action_space
from arena.config import NO_VARIATION
from arena.race import run_race
from slipstream.cli import app
from submissions import load_policy, validate
from submissions.from_graph import GraphSpecError, derive_section
from tests.submissions.test_support import mlp, model

DOC = Path(__file__).resolve().parents[2] / "docs" / "model-format.md"
SECTION = "## Packing a model trained elsewhere"
runner = CliRunner()


def _section() -> str:
    text = DOC.read_text()
    assert SECTION in text
    rest = text.split(SECTION, 1)[1]
    return rest.split("\n## ", 1)[0]


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", _section(), flags=re.S)


@pytest.fixture(scope="module")
def example(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder where the doc's python blocks have run: policy.onnx, model_metadata.json."""
    folder = tmp_path_factory.mktemp("doc_example")
    code = "\n".join(_blocks("python"))
    assert code, "the section has no python block"
    (folder / "example.py").write_text(code)
    done = subprocess.run(
        [sys.executable, "example.py"], cwd=folder, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return folder


def _pack(*args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["model", "pack", *args])
    return result.exit_code, result.output


def test_doc_example_packs_validates_and_races(
    example: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    commands = [line for b in _blocks("sh") for line in b.splitlines()]
    pack_line = next(c for c in commands if c.startswith("slipstream model pack"))
    monkeypatch.chdir(example)
    code, output = _pack(*shlex.split(pack_line)[3:])  # the documented command, verbatim
    assert code == 0, output
    assert "packed" in output and "lidar float32[64]" in output
    archive = example / "model.zip"
    report = validate(archive)
    assert report.ok, report.problems
    assert report.info is not None and report.info.network_preset is None
    policy = load_policy(archive)
    race = make_config(sensors=policy.info.sensors, action_space=policy.info.action_space)
    race = race.model_copy(update={"laps": 1, "time_limit_s": 5.0, "variation": NO_VARIATION})
    raced = run_race(race, {"car0": policy})
    assert raced.car("car0").distance > 0.5


def test_run_form_packs_a_training_run(tmp_path: Path) -> None:
    settings = TrainSettings(
        action_space=parse_action_space_spec("3x3@1.0"),
        sensors=("lidar",),
        workers=0,
        races=1,
        eval_every=1000,
        iterations=1,
    )
    tiny = Hyperparameters(num_episodes_between_training=2, num_epochs=2, batch_size=64)
    Trainer(settings, tmp_path / "run", tiny).run()
    out = tmp_path / "packed.zip"
    code, output = _pack(str(tmp_path / "run"), "--out", str(out))
    assert code == 0, output
    report = validate(out)
    assert report.ok and report.info is not None, report.problems
    assert report.info.network_preset == settings.preset
    assert report.info.training_summary["iterations"] == 1
    assert report.info.has_metrics

    last = tmp_path / "last.zip"
    code, output = _pack(str(tmp_path / "run"), "--out", str(last), "--checkpoint", "last")
    assert code == 0 and validate(last).ok, output
    (tmp_path / "run" / "checkpoints" / "fastest.pt").unlink(missing_ok=True)
    code, output = _pack(str(tmp_path / "run"), "--out", str(out), "--checkpoint", "fastest")
    assert code == 2 and "hasnofastestcheckpoint" in "".join(output.split()), output


def _metadata(tmp_path: Path, **changes: object) -> Path:
    data = {
        "action_space": [
            {"steering_angle": a, "speed": 1.0, "index": i} for i, a in enumerate((-20, 0, 20))
        ],
        "action_space_type": "discrete",
        "sensor": ["LIDAR"],
        "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        "training_algorithm": "clipped_ppo",
        "version": "5",
    }
    data.update(changes)
    path = tmp_path / "model_metadata.json"
    path.write_text(json.dumps({k: v for k, v in data.items() if v is not None}))
    return path


def _disallowed() -> onnx.ModelProto:
    built = mlp(n_out=3)
    built.graph.node[1].op_type = "ThresholdedRelu"  # a real ONNX operator, not allowlisted
    return built


CONTINUOUS = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2}}
FAILURES = {
    "input name": (mlp(n_out=3, input_name="obs"), {}, ["'obs'", "['lidar']", "LIDAR"]),
    "output width": (mlp(n_out=5), {}, ["outputs 5 values", "3 discrete actions"]),
    "continuous width": (
        mlp(n_out=3),
        {"action_space": CONTINUOUS, "action_space_type": "continuous"},
        ["outputs 3 values", "continuous", "2 values"],
    ),
    "no action space": (mlp(n_out=3), {"action_space": None}, ["action_space"]),
    "disallowed op": (_disallowed(), {}, ["not on the allowlist", "ThresholdedRelu"]),
    "opset": (mlp(n_out=3), {}, ["opset", "22"]),
}


@pytest.mark.parametrize("case", list(FAILURES))
def test_a_graph_that_does_not_fit_exits_2_and_writes_nothing(tmp_path: Path, case: str) -> None:
    graph, changes, words = FAILURES[case]
    if case == "opset":
        graph = model(list(graph.graph.node), [*graph.graph.input], [*graph.graph.output],
                      list(graph.graph.initializer), opset=22)  # fmt: skip
    policy = tmp_path / "policy.onnx"
    policy.write_bytes(graph.SerializeToString())
    out = tmp_path / "out" / "model.zip"
    out.parent.mkdir()
    args = ["--onnx", str(policy), "--metadata", str(_metadata(tmp_path, **changes))]
    code, output = _pack(*args, "--out", str(out))
    assert code == 2, output
    for word in words:
        assert word in output, output
    assert list(out.parent.iterdir()) == []


def test_usage_errors_exit_2(tmp_path: Path) -> None:
    assert _pack("--out", str(tmp_path / "m.zip"))[0] == 2
    assert _pack(str(tmp_path), "--onnx", str(tmp_path / "p.onnx"))[0] == 2
    assert _pack("--onnx", str(tmp_path / "p.onnx"))[0] == 2


def _image_graph(name: str, channels: int) -> onnx.ModelProto:
    """(batch, 120, 160, channels) uint8 -> (batch, 3) float32 logits (mean of pixels)."""
    nodes = [
        helper.make_node("Cast", [name], ["f"], to=TensorProto.FLOAT),
        helper.make_node("ReduceMean", ["f"], ["m"], keepdims=0, axes=[1, 2]),
        helper.make_node("Slice", ["m", "zero", "three", "one"], ["out"]),
    ]
    inits = [helper.make_tensor(n, TensorProto.INT64, [1], [v]) for n, v in
             (("zero", 0), ("three", 3), ("one", 1))]  # fmt: skip
    inputs = [helper.make_tensor_value_info(name, TensorProto.UINT8, ["b", 120, 160, channels])]
    outputs = [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["b", 3])]
    return model(nodes, inputs, outputs, inits, opset=17)


SPACE = parse_action_space(
    {"type": "discrete", "actions": [{"steering_angle": a, "speed": 1.0} for a in (-20, 0, 20)]}
)


@pytest.mark.parametrize(
    ("sensor", "graph", "k", "frame"),
    [
        ("camera", _image_graph("camera", 3), 3, 1),  # one grey channel a frame
        ("stereo", _image_graph("stereo", 4), 2, 2),  # two grey channels a frame
        ("lidar", mlp(n_out=3, n_in=64 * 4), 4, 64),  # 64 beams a frame
        ("lidar", mlp(n_out=3), 1, 64),
    ],
)
def test_stack_size_is_read_from_the_input_shape(
    sensor: str, graph: onnx.ModelProto, k: int, frame: int
) -> None:
    section = derive_section(graph.SerializeToString(), SPACE, (sensor,))
    assert section.stack_size == k
    assert section.observation[0].shape[-1] == k * frame
    assert section.output.convention == "logits" and section.output.size == 3


def test_shapes_that_are_no_stack_are_refused() -> None:
    with pytest.raises(GraphSpecError, match=r"shape \(batch, 100\)"):
        derive_section(mlp(n_out=3, n_in=100).SerializeToString(), SPACE, ("lidar",))
    with pytest.raises(GraphSpecError, match="must be uint8"):
        derive_section(mlp(n_out=3, input_name="camera").SerializeToString(), SPACE, ("camera",))


def test_stacked_graph_packs(tmp_path: Path) -> None:
    policy = tmp_path / "policy.onnx"
    policy.write_bytes(mlp(n_out=3, n_in=128).SerializeToString())
    out = tmp_path / "model.zip"
    args = ["--onnx", str(policy), "--metadata", str(_metadata(tmp_path)), "--out", str(out)]
    code, output = _pack(*args)
    assert code == 0, output
    assert "2 stacked frames" in output
    report = validate(out)
    assert report.ok and report.info is not None, report.problems
    assert report.info.observation[0].shape == (128,)
