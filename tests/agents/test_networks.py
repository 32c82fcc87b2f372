"""Network presets, hyperparameter mapping and ONNX export."""

from __future__ import annotations

import json

import numpy as np
import onnxruntime as ort
import pytest
import torch
from tensordict import TensorDict

from agents import networks
from agents.export import example_inputs, export_onnx
from agents.hyperparameters import Hyperparameters
from agents.selfplay import pfsp_weights
from arena.actions import ContinuousActionSpace, DiscreteActionSpace, default_discrete_space

DISCRETE = default_discrete_space()
CONTINUOUS = ContinuousActionSpace()

CASES = [
    ("3-layer CNN", ("camera",), DISCRETE),
    ("5-layer CNN", ("stereo",), DISCRETE),
    ("3-layer CNN", ("camera", "lidar"), CONTINUOUS),
    ("CPU CNN", ("camera",), CONTINUOUS),
    ("dense 256-256", ("lidar",), DISCRETE),
    ("dense 256-256", ("sector_lidar",), CONTINUOUS),
    ("dense 256-256", ("discretized_sector_lidar",), DISCRETE),
]


@pytest.mark.parametrize(("preset", "sensors", "space"), CASES)
def test_preset_forward(preset, sensors, space):
    actor = networks.build_actor(preset, sensors, space)
    obs = networks.example_observations(sensors, batch=3)
    out = actor(obs, stochastic_output=True)
    assert out.shape == (3, networks.num_actions(space))
    if isinstance(space, DiscreteActionSpace):
        assert torch.all(out.sum(dim=1) == 1)  # one-hot samples


def test_three_layer_cnn_matches_deepracer_layers():
    actor = networks.build_actor("3-layer CNN", ("camera",), DISCRETE)
    convs = [m for m in actor.cnns["camera"] if isinstance(m, torch.nn.Conv2d)]
    assert [(c.out_channels, c.kernel_size[0], c.stride[0]) for c in convs] == [
        (32, 8, 4),
        (64, 4, 2),
        (64, 3, 1),
    ]
    linears = [m for m in actor.mlp if isinstance(m, torch.nn.Linear)]
    assert linears[0].out_features == 512


def test_preset_sensor_mismatch_is_refused():
    with pytest.raises(ValueError, match="needs a camera"):
        networks.check_preset("3-layer CNN", ("lidar",))
    with pytest.raises(ValueError, match="cannot read a camera"):
        networks.check_preset("dense 256-256", ("camera",))
    with pytest.raises(ValueError, match="unknown network preset"):
        networks.check_preset("7-layer CNN", ("camera",))


def test_hyperparameters_map_to_rsl_rl(tmp_path):
    hp = Hyperparameters(batch_size=128, num_epochs=4, lr=1e-4, beta_entropy=0.02)
    actor, critic, groups = networks.model_configs("dense 256-256", ("lidar",), DISCRETE)
    cfg = hp.to_rsl_rl(4, actor, critic, groups, num_steps_per_env=64)
    alg = cfg["algorithm"]
    assert alg["learning_rate"] == 1e-4
    assert alg["num_learning_epochs"] == 4
    assert alg["num_mini_batches"] == 2  # 4 x 64 samples / 128
    assert alg["entropy_coef"] == 0.02
    assert alg["gamma"] == 0.999 and alg["lam"] == 0.95 and alg["clip_param"] == 0.2
    written = json.loads(hp.write(tmp_path).read_text())
    assert written["batch_size"] == 128 and written["loss_type"] == "huber"
    assert set(written) >= {"e_greedy_value", "epsilon_steps", "exploration_type", "stack_size"}


@pytest.mark.parametrize(("slots", "grow", "samples", "minibatch"), [
    (8, False, 1280, 64),  # DeepRacer's 20 episodes of 64 steps, batch 64
    (56, False, 1288, 64),  # as written: the iteration stays about 20 episodes
    (56, True, 8960, 448),  # grown: 160 steps a slot, each minibatch 7 times larger
    (4, True, 1280, 64),  # fewer slots than the reference machine's: as written
])  # fmt: skip
def test_an_iteration_grows_with_the_races_keeping_deepracers_gradient_steps(
    slots: int, grow: bool, samples: int, minibatch: int
) -> None:
    hp = Hyperparameters()  # batch 64, 10 epochs, 20 episodes between training
    actor, critic, groups = networks.model_configs("dense 256-256", ("lidar",), DISCRETE)
    cfg = hp.to_rsl_rl(slots, actor, critic, groups, grow=grow)
    alg = cfg["algorithm"]
    assert cfg["num_steps_per_env"] * slots == samples
    assert alg["num_mini_batches"] == 20 and alg["num_learning_epochs"] == 10
    assert samples / alg["num_mini_batches"] == pytest.approx(minibatch, rel=0.01)


def test_a_fixed_rollout_length_does_not_grow():
    actor, critic, groups = networks.model_configs("dense 256-256", ("lidar",), DISCRETE)
    cfg = Hyperparameters().to_rsl_rl(28, actor, critic, groups, num_steps_per_env=64, grow=True)
    assert cfg["num_steps_per_env"] == 64 and cfg["algorithm"]["num_mini_batches"] == 28


@pytest.mark.parametrize(
    ("preset", "sensors", "space"),
    [CASES[0], CASES[2], CASES[3]],
)
def test_onnx_export_matches_torch(preset, sensors, space):
    torch.manual_seed(0)
    actor = networks.build_actor(preset, sensors, space).eval()
    graph = export_onnx(actor, sensors, space)
    session = ort.InferenceSession(graph, providers=["CPUExecutionProvider"])
    raw = example_inputs(sensors, batch=5, seed=1)
    (onnx_out,) = session.run(None, raw)
    with torch.inference_mode():
        torch_out = actor(networks.observation_groups(raw))
    if isinstance(space, DiscreteActionSpace):
        assert np.array_equal(onnx_out.argmax(axis=1), torch_out.numpy().argmax(axis=1))
    else:
        np.testing.assert_allclose(onnx_out, torch_out.clamp(-1, 1).numpy(), atol=1e-5)


def test_channels_last_weights_keep_the_actor_its_outputs_and_its_export():
    torch.manual_seed(0)
    actor = networks.build_actor("CPU CNN", ("camera",), CONTINUOUS).eval()
    raw = example_inputs(("camera",), batch=5, seed=3)
    with torch.inference_mode():
        before = actor(networks.observation_groups(raw))
    state = {k: v.clone() for k, v in actor.state_dict().items()}
    networks.channels_last([actor])
    conv = next(m for m in actor.modules() if isinstance(m, torch.nn.Conv2d))
    assert conv.weight.is_contiguous(memory_format=torch.channels_last)
    with torch.inference_mode():
        after = actor(networks.observation_groups(raw))
    torch.testing.assert_close(after, before, atol=1e-5, rtol=1e-5)
    assert all(torch.equal(v, state[k]) for k, v in actor.state_dict().items())
    session = ort.InferenceSession(export_onnx(actor, ("camera",), CONTINUOUS))
    (onnx_out,) = session.run(None, raw)
    np.testing.assert_allclose(onnx_out, after.clamp(-1, 1).numpy(), atol=1e-5)


def test_pfsp_prefers_opponents_the_learner_loses_to():
    weights = pfsp_weights([0.9, 0.5, 0.1])
    assert weights.sum() == pytest.approx(1.0)
    assert weights[2] > weights[1] > weights[0] > 0


def _camera_rollout(steps: int = 3, envs: int = 4) -> TensorDict:
    torch.manual_seed(0)
    camera = torch.rand(steps, envs, 1, 120, 160)
    lidar = torch.rand(steps, envs, 64)
    return TensorDict({"camera": camera, "lidar": lidar}, batch_size=[steps, envs])


def test_an_update_may_read_the_images_pooled_once_with_the_same_results():
    actor = networks.build_actor("CPU CNN", ("camera", "lidar"), DISCRETE)
    rollout = _camera_rollout()
    full = rollout["camera"]
    with torch.no_grad():
        expected = actor(rollout.flatten(0, 1))
        with networks.images_pooled_once([actor], rollout):
            assert rollout["camera"].shape == (3, 4, 1, 30, 40)
            assert rollout["lidar"].shape == (3, 4, 64)  # not an image: as it was
            pooled = actor(rollout.flatten(0, 1))
    torch.testing.assert_close(pooled, expected)
    assert rollout["camera"] is full  # the rollout and the network are as they were
    assert isinstance(actor.cnns["camera"][0], torch.nn.AvgPool2d)


def test_images_another_network_reads_unpooled_stay_unpooled():
    pooled_cnn = networks.build_actor("CPU CNN", ("camera",), DISCRETE)
    plain_cnn = networks.build_actor("3-layer CNN", ("camera",), DISCRETE)
    rollout = _camera_rollout()
    with networks.images_pooled_once([pooled_cnn, plain_cnn], rollout):
        assert rollout["camera"].shape == (3, 4, 1, 120, 160)
        assert isinstance(pooled_cnn.cnns["camera"][0], torch.nn.AvgPool2d)


@pytest.mark.parametrize("frames", [1, 3])
def test_images_reach_the_policy_row_by_row_with_the_camera_s_values(frames):
    """C x H x W images in [0, 1] with NCHW strides (one-channel channels-last pooling
    halved the forward pass's speed), the same numbers as the camera's pixels / 255."""
    pixels = np.random.default_rng(0).integers(0, 256, (4, 120, 160, frames), dtype=np.uint8)
    images = networks.observation_groups({"camera": pixels})["camera"]
    assert images.shape == (4, frames, 120, 160) and images.dtype == torch.float32
    assert images.stride() == torch.empty(images.shape).stride()
    expected = torch.from_numpy(pixels).permute(0, 3, 1, 2).float() / 255.0
    assert torch.equal(images, expected)
