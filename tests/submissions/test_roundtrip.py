"""Pack -> validate -> load -> act, with torch-exported and hand-built policies."""

from __future__ import annotations

import io
import json
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper
from torch import nn

from arena.actions import ContinuousActionSpace
from arena.policy import Policy
from arena.sensors_spec import LidarConfig, observation_space
from submissions import (
    FORMAT_VERSION,
    InvalidSubmission,
    OnnxPolicy,
    load_policy,
    pack,
    validate,
)
from tests.submissions.test_support import CREATED_AT, DISCRETE, model, pack_bytes, tensor


class LidarMLP(nn.Module):
    def __init__(self, n_out: int) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(64, 32), nn.Tanh(), nn.Linear(32, n_out))

    def forward(self, lidar: torch.Tensor) -> torch.Tensor:
        return self.net(lidar)


class CameraCNN(nn.Module):
    """uint8 NHWC camera -> two actions in [-1, 1]."""

    def __init__(self) -> None:
        super().__init__()
        self.conv = nn.Sequential(
            nn.Conv2d(1, 8, 8, stride=4), nn.ReLU(), nn.Conv2d(8, 16, 4, stride=2), nn.ReLU()
        )
        self.head = nn.Linear(16 * 13 * 18, 2)

    def forward(self, camera: torch.Tensor) -> torch.Tensor:
        x = camera.to(torch.float32).permute(0, 3, 1, 2) / 255.0
        return torch.tanh(self.head(torch.flatten(self.conv(x), 1)))


def export(module: nn.Module, example: torch.Tensor, name: str, out: str) -> bytes:
    """torch.onnx.export (the default exporter) with a symbolic batch dimension."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "policy.onnx"
        torch.onnx.export(
            module.eval(),
            (example,),
            path,
            input_names=[name],
            output_names=[out],
            dynamic_shapes=({0: torch.export.Dim.DYNAMIC},),
            external_data=False,
        )
        return path.read_bytes()


@pytest.fixture(scope="module")
def lidar_module() -> nn.Module:
    torch.manual_seed(0)
    return LidarMLP(DISCRETE.n).eval()


@pytest.fixture(scope="module")
def camera_module() -> nn.Module:
    torch.manual_seed(1)
    return CameraCNN().eval()


@pytest.fixture(scope="module")
def lidar_zip(lidar_module: nn.Module, tmp_path_factory: pytest.TempPathFactory) -> Path:
    policy = export(lidar_module, torch.rand(2, 64), "lidar", "logits")
    out = tmp_path_factory.mktemp("lidar") / "lidar.zip"
    return pack(
        out,
        policy,
        DISCRETE,
        ["LIDAR"],
        neural_network="LIDAR_MLP",
        network_preset="lidar dense 256-256",
        training_summary={"track": "reInvent2019_track", "iterations": 3, "best_lap_s": 9.5},
        reward_function="def reward_function(params):\n    return 1.0\n",
        metrics_csv=b"iteration,reward\n0,1.0\n",
        created_at=CREATED_AT,
    )


@pytest.fixture(scope="module")
def camera_zip(camera_module: nn.Module, tmp_path_factory: pytest.TempPathFactory) -> Path:
    example = torch.randint(0, 256, (2, 120, 160, 1), dtype=torch.uint8)
    policy = export(camera_module, example, "camera", "action")
    out = tmp_path_factory.mktemp("camera") / "camera.zip"
    space = ContinuousActionSpace(steering_angle={"low": -20, "high": 20})
    return pack(out, policy, space, ["camera"], network_preset="3-layer CNN", created_at=CREATED_AT)


def _observations(sensors: tuple[str, ...], n: int, lidar: LidarConfig | None = None):
    space = observation_space(sensors, lidar)
    space.seed(0)
    return [space.sample() for _ in range(n)]


@pytest.mark.slow
def test_lidar_mlp_round_trip(lidar_zip: Path, lidar_module: nn.Module) -> None:
    report = validate(lidar_zip)
    assert report.ok, report.problems
    info = report.info
    assert info is not None
    assert info.sensors == ("lidar",) and info.output.convention == "logits"
    assert info.training_summary["track"] == "reInvent2019_track"
    assert info.has_reward_function and info.has_metrics and info.format_version == FORMAT_VERSION
    policy = load_policy(lidar_zip)
    assert isinstance(policy, Policy)
    policy.reset()
    for obs in _observations(("lidar",), 20):
        action = policy.act(obs)
        assert isinstance(action, int) and DISCRETE.gym_space().contains(action)
        with torch.no_grad():
            expected = int(lidar_module(torch.from_numpy(obs["lidar"])[None]).argmax())
        assert action == expected


@pytest.mark.slow
def test_camera_cnn_round_trip(camera_zip: Path, camera_module: nn.Module) -> None:
    report = validate(camera_zip)
    assert report.ok, report.problems
    assert report.info is not None and report.info.network_preset == "3-layer CNN"
    policy = load_policy(camera_zip.read_bytes())
    box = ContinuousActionSpace().gym_space()
    observations = _observations(("camera",), 5)
    for obs in observations:
        action = policy.act(obs)
        assert action.shape == (2,) and box.contains(action)
        with torch.no_grad():
            expected = camera_module(torch.from_numpy(obs["camera"])[None])[0].numpy()
        np.testing.assert_allclose(action, expected, atol=1e-4)
    batch = {"camera": np.stack([o["camera"] for o in observations])}
    assert policy.act_batch(batch).shape == (5, 2)


def test_pack_is_deterministic_and_load_rejects_invalid(tmp_path: Path) -> None:
    first = pack_bytes(
        _multi_sensor_graph(), ContinuousActionSpace(), ("STEREO_CAMERAS", "sector_lidar")
    )
    second = pack_bytes(_multi_sensor_graph(), ContinuousActionSpace(), ("stereo", "SECTOR_LIDAR"))
    assert first == second
    with zipfile.ZipFile(io.BytesIO(first)) as zf:
        assert [i.date_time for i in zf.infolist()] == [(1980, 1, 1, 0, 0, 0)] * 2
    broken = tmp_path / "broken.zip"
    broken.write_bytes(first[:-30])
    with pytest.raises(InvalidSubmission) as caught:
        load_policy(broken)
    assert caught.value.report.problems[0].field == "archive"


def _multi_sensor_graph() -> onnx.ModelProto:
    """stereo (uint8) + sector lidar -> 2 actions: mean of each camera, concat, dense, tanh."""
    nodes = [
        helper.make_node("Cast", ["stereo"], ["s"], to=TensorProto.FLOAT),
        helper.make_node("ReduceMean", ["s"], ["m"], axes=[1, 2], keepdims=0),
        helper.make_node("Concat", ["m", "sector_lidar"], ["x"], axis=1),
        helper.make_node("Gemm", ["x", "w", "b"], ["y"]),
        helper.make_node("Tanh", ["y"], ["action"]),
    ]
    inputs = [
        helper.make_tensor_value_info("stereo", TensorProto.UINT8, ["n", 120, 160, 2]),
        helper.make_tensor_value_info("sector_lidar", TensorProto.FLOAT, ["n", 8]),
    ]
    outputs = [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["n", 2])]
    w = np.linspace(-0.01, 0.01, 20, dtype=np.float32).reshape(10, 2)
    return model(nodes, inputs, outputs, [tensor("w", w), tensor("b", np.zeros(2, np.float32))])


def _multi_sensor_reference(obs: dict[str, np.ndarray]) -> np.ndarray:
    """What ``_multi_sensor_graph`` computes, in numpy (b is zero)."""
    w = np.linspace(-0.01, 0.01, 20, dtype=np.float32).reshape(10, 2)
    camera_means = obs["stereo"].astype(np.float32).mean(axis=(0, 1))
    return np.tanh(np.concatenate([camera_means, obs["sector_lidar"]]) @ w)


def test_multi_sensor_policy_acts() -> None:
    archive = pack_bytes(_multi_sensor_graph(), ContinuousActionSpace(), ("stereo", "sector_lidar"))
    policy = load_policy(archive)
    assert isinstance(policy, OnnxPolicy)
    meta = json.loads(zipfile.ZipFile(io.BytesIO(archive)).read("model_metadata.json"))
    assert meta["sensor"] == ["STEREO_CAMERAS", "SECTOR_LIDAR"]
    assert [i["name"] for i in meta["slipstream"]["observation"]] == ["stereo", "sector_lidar"]
    actions = []
    for obs in _observations(("stereo", "sector_lidar"), 5):
        action = policy.act(obs)
        assert action.dtype == np.float32 and action.shape == (2,)
        np.testing.assert_allclose(action, _multi_sensor_reference(obs), rtol=1e-5, atol=1e-6)
        actions.append(action)
    assert len({a.tobytes() for a in actions}) == len(actions)  # each input gives its own


def test_pack_refuses_bad_parts(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown sensor"):
        pack(tmp_path / "x.zip", b"", DISCRETE, ["radar"])
    with pytest.raises(ValueError):
        pack(tmp_path / "x.zip", b"", {"type": "discrete", "actions": []}, ["lidar"])
