"""The CPU-sized camera preset (export, submission, raw-input agreement) and return scaling."""

from __future__ import annotations

import numpy as np
import onnxruntime as ort
import pytest
import torch

import arena
from agents import networks
from agents.export import example_inputs, export_onnx, pack_model
from agents.hyperparameters import Hyperparameters
from agents.return_scale import ReturnScale
from agents.runner import RacingRunner
from agents.vecenv import RacingVecEnv
from arena.actions import ContinuousActionSpace, default_discrete_space
from submissions import validate
from tests.agents.bandit import Bandit, ppo_config

PRESET = "CPU CNN"
CONTINUOUS = ContinuousActionSpace()


@pytest.mark.parametrize(
    ("sensors", "space"),
    [(("camera",), CONTINUOUS), (("camera", "lidar"), default_discrete_space())],
)
def test_cpu_cnn_exports_and_matches_torch_on_raw_camera(sensors, space):
    torch.manual_seed(0)
    actor = networks.build_actor(PRESET, sensors, space).eval()
    assert isinstance(actor.cnns["camera"][0], torch.nn.AvgPool2d)
    session = ort.InferenceSession(export_onnx(actor, sensors, space))
    raw = example_inputs(sensors, batch=4, seed=2)
    assert raw["camera"].dtype == np.uint8 and raw["camera"].shape[1:3] == (120, 160)
    (onnx_out,) = session.run(None, raw)
    with torch.inference_mode():
        torch_out = actor(networks.observation_groups(raw))
    if space is CONTINUOUS:
        np.testing.assert_allclose(onnx_out, torch_out.clamp(-1, 1).numpy(), atol=1e-5)
    else:  # logits in the graph, the one-hot greedy action in torch
        assert np.array_equal(onnx_out.argmax(axis=1), torch_out.numpy().argmax(axis=1))


def test_cpu_cnn_packs_as_a_valid_submission(tmp_path):
    actor = networks.build_actor(PRESET, ("camera",), CONTINUOUS).eval()
    out = pack_model(
        tmp_path / "model.zip",
        export_onnx(actor, ("camera",), CONTINUOUS),
        CONTINUOUS,
        ("camera",),
        neural_network=networks.deepracer_network_name(PRESET),
        network_preset=PRESET,
        lidar=None,
        training_summary={},
        reward_source=None,
        metrics_csv=None,
    )
    report = validate(out)
    assert report.ok, report.problems


def test_cpu_cnn_is_much_smaller_than_the_deepracer_preset():
    def size(preset: str) -> int:
        actor = networks.build_actor(preset, ("camera",), CONTINUOUS)
        return sum(p.numel() for p in actor.parameters())

    assert size(PRESET) * 20 < size("3-layer CNN")


def test_cpu_cnn_critic_gets_the_huber_variant_and_ppo_scales_returns():
    actor, critic, groups = networks.model_configs(PRESET, ("camera",), CONTINUOUS)
    cfg = Hyperparameters().to_rsl_rl(1, actor, critic, groups)
    assert cfg["actor"]["class_name"] == "agents.networks:PooledCNNModel"
    assert cfg["critic"]["class_name"] == "agents.huber:HuberPooledCNNModel"
    assert cfg["algorithm"]["class_name"] == "agents.return_scale:ReturnScaledPPO"


def test_return_scale_is_invariant_to_the_reward_scale():
    torch.manual_seed(0)
    rewards = torch.rand(50, 4, 1)
    dones = torch.rand(50, 4) < 0.05
    small, large = ReturnScale(0.99), ReturnScale(0.99)
    for r, d in zip(rewards, dones, strict=True):
        a, b = small(r, d), large(1000.0 * r, d)
    torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
    assert set(small.state_dict()["_extra_state"]) == {"count", "mean", "var"}


def _value_loss(reward_file: str) -> float:
    config = arena.make_config(sensors=("lidar",), action_space=CONTINUOUS, mode="training", seed=0)
    env = RacingVecEnv(config, reward_file, num_races=1, num_workers=0, record_simtrace=False)
    try:
        actor, critic, groups = networks.model_configs("dense 256-256", ("lidar",), CONTINUOUS)
        hp = Hyperparameters(num_epochs=2, batch_size=64, discount_factor=0.99)
        cfg = hp.to_rsl_rl(env.num_envs, actor, critic, groups, num_steps_per_env=64)
        torch.manual_seed(0)
        runner = RacingRunner(env, cfg, log_dir=None, device="cpu")
        runner.start()
        return [runner.iteration(it) for it in range(3)][-1]["value"]
    finally:
        env.close()


def test_value_loss_does_not_grow_with_the_reward_scale(tmp_path):
    body = "def reward_function(params):\n    return {} * float(params['speed'])\n"
    (tmp_path / "r1.py").write_text(body.format(1.0))
    (tmp_path / "r1000.py").write_text(body.format(1000.0))
    unscaled = _value_loss(str(tmp_path / "r1.py"))
    scaled = _value_loss(str(tmp_path / "r1000.py"))
    assert 0.0 < scaled < 10.0 * unscaled + 1e-3 and unscaled < 10.0 * scaled + 1e-3
    assert scaled < 10.0


def test_return_scale_is_saved_and_loaded_with_the_critic():
    cfg = ppo_config("GaussianDistribution")
    cfg["algorithm"]["class_name"] = "agents.return_scale:ReturnScaledPPO"
    trained = RacingRunner(Bandit(), cfg, log_dir=None, device="cpu")
    trained.learn(2)
    state = trained.alg.save()
    fresh = RacingRunner(Bandit(), {**cfg, "algorithm": dict(cfg["algorithm"])}, None, "cpu")
    fresh.alg.load(state, {"actor": True, "critic": True}, strict=True)
    assert fresh.alg.return_scale.count == trained.alg.return_scale.count > 100
    old = {k: v for k, v in state.items() if k != "return_scale_state_dict"}
    fresh.alg.load(old, None, strict=True)  # a checkpoint from before the scaling loads
