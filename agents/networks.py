"""Network presets by DeepRacer name, as rsl-rl actor/critic model configs.

Every sensor is its own observation group, named after the sensor: images arrive as
``(C, H, W)`` float tensors in ``[0, 1]`` and go through rsl-rl's CNN encoders; 1D
sensors (lidars) are concatenated with the CNN latent (``CNNModel``) or form the whole
input (``MLPModel``).

=================  ====================================================================
preset             layers
=================  ====================================================================
``3-layer CNN``    conv 32/8/4, 64/4/2, 64/3/1 -> dense 512 (DeepRacer's
                   ``DEEP_CONVOLUTIONAL_NETWORK_SHALLOW``), ReLU
``5-layer CNN``    conv 32/5/2, 32/3/1, 64/3/2, 64/3/1, 128/3/2 -> dense 512
                   (``DEEP_CONVOLUTIONAL_NETWORK``; layer sizes unverified), ReLU
``CPU CNN``        average pool 4 (120 x 160 -> 30 x 40), conv 16/5/2, 32/3/2, 32/3/1
                   -> dense 256, ReLU: about 14x cheaper than ``3-layer CNN`` per update
                   (no DeepRacer name; metadata says ``DEEP_CONVOLUTIONAL_NETWORK_SHALLOW``)
``dense 256-256``  dense 256, 256 (lidar and sector lidars), ReLU
=================  ====================================================================
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from typing import Any, get_args

import numpy as np
import torch
from rsl_rl.models import CNNModel
from tensordict import TensorDict
from torch import nn

from agents.privileged import PRIVILEGED_GROUP, CriticInput
from arena.actions import ContinuousActionSpace, DiscreteActionSpace
from arena.sensors_spec import IMAGE_SENSORS, LidarConfig, check_sensors, sensor_space

CATEGORICAL = "agents.distributions:CategoricalDistribution"

_CNN_LAYERS: dict[str, tuple[list[int], list[int], list[int]]] = {
    "3-layer CNN": ([32, 64, 64], [8, 4, 3], [4, 2, 1]),
    "5-layer CNN": ([32, 32, 64, 64, 128], [5, 3, 3, 3, 3], [2, 1, 2, 1, 2]),
    "CPU CNN": ([16, 32, 32], [5, 3, 3], [2, 2, 1]),
}
POOLED_CNN = "agents.networks:PooledCNNModel"
# How the policy's images are laid out in memory: row by row (NCHW). An H x W x C image
# permuted to C x H x W has channels-last strides, and with one or two channels PyTorch's
# channels-last pooling made the policy's forward pass about twice as slow
# (benchmarks/RESULTS.md, "Images laid out row by row").
IMAGE_LAYOUT = torch.contiguous_format
# The critic of ``--critic privileged``: an MLP on the privileged state, inputs normalised
# by running statistics (its features have different scales).
PRIVILEGED_CRITIC: dict[str, Any] = {
    "class_name": "MLPModel",
    "hidden_dims": [256, 256],
    "activation": "relu",
    "obs_normalization": True,
}
PRESETS: dict[str, dict[str, Any]] = {
    "3-layer CNN": {"deepracer": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW", "hidden": [512]},
    "5-layer CNN": {"deepracer": "DEEP_CONVOLUTIONAL_NETWORK", "hidden": [512]},
    "CPU CNN": {"deepracer": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW", "hidden": [256], "pool": 4},
    "dense 256-256": {"deepracer": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW", "hidden": [256, 256]},
}


def default_preset(sensors: tuple[str, ...] | list[str]) -> str:
    """``CPU CNN`` when a camera is fitted (it trains on a CPU in a tenth of the time of
    DeepRacer's ``3-layer CNN``: benchmarks/RESULTS.md), else ``dense 256-256``."""
    return "CPU CNN" if any(s in IMAGE_SENSORS for s in sensors) else "dense 256-256"


def check_preset(preset: str, sensors: tuple[str, ...] | list[str]) -> None:
    """Refuse a preset that cannot read the sensors (raises ``ValueError``)."""
    if preset not in PRESETS:
        raise ValueError(f"unknown network preset {preset!r}; choose from {list(PRESETS)}")
    has_camera = any(s in IMAGE_SENSORS for s in sensors)
    if has_camera and preset not in _CNN_LAYERS:
        cnns = ", ".join(repr(p) for p in _CNN_LAYERS)
        raise ValueError(f"{preset!r} cannot read a camera; use one of {cnns}")
    if not has_camera and preset in _CNN_LAYERS:
        raise ValueError(f"{preset!r} needs a camera; use 'dense 256-256' for lidars")


class PooledCNNModel(CNNModel):
    """rsl-rl's ``CNNModel`` whose CNN encoders first average-pool their image by ``pool``.

    The pooling is part of each encoder (``cnns[group]`` is ``AvgPool2d`` then rsl-rl's
    ``CNN``), so the exported graph pools too (ONNX ``AveragePool``).
    """

    def __init__(self, *args: Any, pool: int = 1, **kwargs: Any) -> None:
        self.pool = pool
        super().__init__(*args, **kwargs)
        if pool > 1:
            self.cnns = nn.ModuleDict(
                {g: nn.Sequential(nn.AvgPool2d(pool), cnn) for g, cnn in self.cnns.items()}
            )

    def _get_obs_dim(self, *args: Any) -> tuple[list[str], int]:
        """As ``CNNModel``'s, with the image sizes the pooling leaves for the CNNs."""
        result = super()._get_obs_dim(*args)
        self.obs_dims_2d = [(h // self.pool, w // self.pool) for h, w in self.obs_dims_2d]
        return result


@contextlib.contextmanager
def images_pooled_once(models: Sequence[nn.Module], observations: TensorDict) -> Iterator[None]:
    """Within the block, ``observations`` (a rollout's) hold their images already pooled
    and the :class:`PooledCNNModel` encoders of ``models`` skip their pooling.

    An update reads each image once per epoch: pooling the rollout once instead gives the
    same numbers (the same pooling of the same images), with less pooling and 1/pool^2 of
    the image data gathered per minibatch. A group is pooled only when every model that
    reads it pools it alike; both are restored on leaving, the images in place.
    """
    readers: dict[str, list[nn.Module]] = {}  # group -> the models reading it as an image
    flat: set[str] = set()  # groups some model reads as a vector
    for model in models:
        flat.update(getattr(model, "obs_groups", []))
        for group in getattr(model, "obs_groups_2d", []):
            readers.setdefault(group, []).append(model)
    pools = {
        group: models_of[0].pool
        for group, models_of in readers.items()
        if group not in flat
        and all(isinstance(m, PooledCNNModel) and m.pool > 1 for m in models_of)
        and len({m.pool for m in models_of}) == 1
    }
    if not pools:
        yield
        return
    full = {group: observations[group] for group in pools}
    encoders = [(m, group, m.cnns[group]) for group in pools for m in readers[group]]
    for group, pool in pools.items():
        images = full[group].flatten(0, 1)
        pooled = nn.functional.avg_pool2d(images, pool)
        observations.set(group, pooled.view(*full[group].shape[:2], *pooled.shape[1:]))
    for model, group, encoder in encoders:
        model.cnns[group] = encoder[1]  # the CNN after the AvgPool2d
    try:
        yield
    finally:
        for model, group, encoder in encoders:
            model.cnns[group] = encoder
        for group, images in full.items():
            observations.set(group, images)


def channels_last(models: Sequence[nn.Module]) -> None:
    """Hold the convolution weights of ``models`` channels-last, in place, for CPU training.

    On a CPU, oneDNN's kernels for these small convolutions run about 1.25x faster forward
    and backward with channels-last weights (their outputs follow), the same numbers to
    rounding (benchmarks/RESULTS.md, "Channels-last convolutions"). Only the memory
    layout changes: the parameters stay the same objects, state dicts and exports the same.
    """
    for model in models:
        model.to(memory_format=torch.channels_last)


def deepracer_network_name(preset: str) -> str:
    """The ``neural_network`` value written to ``model_metadata.json``."""
    return PRESETS[preset]["deepracer"]


def example_observations(
    sensors: tuple[str, ...] | list[str],
    lidar: LidarConfig | None = None,
    batch: int = 1,
    stack_size: int = 1,
) -> TensorDict:
    """Zero observations of the right group shapes (images as ``C x H x W`` floats, the
    ``stack_size`` frames' channels stacked)."""
    groups = {}
    for name in check_sensors(sensors):
        shape = sensor_space(name, lidar, stack_size).shape
        if name in IMAGE_SENSORS:
            shape = (shape[2], shape[0], shape[1])
        groups[name] = torch.zeros((batch, *shape))
    return TensorDict(groups, batch_size=[batch])


def observation_groups(
    arrays: dict[str, np.ndarray], device: str | torch.device = "cpu"
) -> TensorDict:
    """Batched raw sensor arrays as the policy's groups (images ``C x H x W`` in ``[0, 1]``,
    laid out row by row: see :data:`IMAGE_LAYOUT`)."""
    groups = {}
    for name, value in arrays.items():
        data = torch.from_numpy(np.ascontiguousarray(value))
        if name in IMAGE_SENSORS:
            data = data.permute(0, 3, 1, 2).to(torch.float32, memory_format=IMAGE_LAYOUT)
            data = data.div(255.0)
        groups[name] = data.float().to(device)
    batch = next(iter(groups.values())).shape[0]
    return TensorDict(groups, batch_size=[batch], device=device)


def model_configs(
    preset: str,
    sensors: tuple[str, ...] | list[str],
    action_space: DiscreteActionSpace | ContinuousActionSpace,
    critic_input: CriticInput = "sensors",
) -> tuple[dict[str, Any], dict[str, Any], dict[str, list[str]]]:
    """``(actor_cfg, critic_cfg, obs_groups)`` for rsl-rl's runner config.

    The actor reads the sensors. The critic reads them too (``critic_input="sensors"``,
    the same network as the actor's) or, with ``"privileged"``, only the privileged-state
    group (:mod:`agents.privileged`) through :data:`PRIVILEGED_CRITIC`.
    """
    check_preset(preset, sensors)
    names = list(check_sensors(sensors))
    base: dict[str, Any] = {
        "hidden_dims": list(PRESETS[preset]["hidden"]),
        "activation": "relu",
        "obs_normalization": False,
    }
    if preset in _CNN_LAYERS:
        channels, kernels, strides = _CNN_LAYERS[preset]
        pool = PRESETS[preset].get("pool", 1)
        base["class_name"] = POOLED_CNN if pool > 1 else "CNNModel"
        if pool > 1:
            base["pool"] = pool
        base["cnn_cfg"] = {
            "output_channels": channels,
            "kernel_size": kernels,
            "stride": strides,
            "activation": "relu",
            "flatten": True,
        }
    else:
        base["class_name"] = "MLPModel"
    if isinstance(action_space, DiscreteActionSpace):
        distribution = {"class_name": CATEGORICAL}
    else:
        distribution = {"class_name": "GaussianDistribution", "init_std": 0.5}
    actor = {**base, "distribution_cfg": distribution}
    if critic_input == "privileged":
        return actor, dict(PRIVILEGED_CRITIC), {"actor": names, "critic": [PRIVILEGED_GROUP]}
    if critic_input != "sensors":
        choices = " or ".join(get_args(CriticInput))
        raise ValueError(f"unknown critic input {critic_input!r}; use {choices}")
    return actor, dict(base), {"actor": names, "critic": names}


def num_actions(action_space: DiscreteActionSpace | ContinuousActionSpace) -> int:
    """Width of the actor's output: ``n`` one-hot entries, or 2 continuous values."""
    return action_space.n if isinstance(action_space, DiscreteActionSpace) else 2


def build_actor(
    preset: str,
    sensors: tuple[str, ...] | list[str],
    action_space: DiscreteActionSpace | ContinuousActionSpace,
    lidar: LidarConfig | None = None,
    stack_size: int = 1,
) -> torch.nn.Module:
    """A fresh actor model (outside a runner), e.g. to load a checkpoint for evaluation."""
    from rsl_rl.utils import resolve_callable

    actor_cfg, _, obs_groups = model_configs(preset, sensors, action_space)
    cfg = dict(actor_cfg)
    model_class = resolve_callable(cfg.pop("class_name"))
    obs = example_observations(sensors, lidar, stack_size=stack_size)
    return model_class(obs, obs_groups, "actor", num_actions(action_space), **cfg)
