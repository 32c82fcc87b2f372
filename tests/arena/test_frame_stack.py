"""Frame stacking (DeepRacer's ``stack_size``): each sensor's last k frames, oldest first."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

import arena
from arena.config import CarConfig, RaceConfig
from arena.drivers import LaneFollowerPolicy
from arena.env import RacingEnv
from arena.sensors_spec import SENSOR_NAMES, observation_space, sensor_space

FULL_LOCK = 1  # -30 deg at 0.8 m/s: drives off the track to the right


def stacked(config: RaceConfig, k: int, cars: tuple[str, ...] | None = None) -> RaceConfig:
    """``config`` with ``cars`` (default: all) stacking ``k`` frames."""
    return config.model_copy(
        update={
            "cars": tuple(
                c.model_copy(update={"stack_size": k}) if cars is None or c.name in cars else c
                for c in config.cars
            )
        }
    )


def frames_of(obs: dict[str, np.ndarray], frame: dict[str, np.ndarray], k: int) -> list[dict]:
    """The ``k`` frames held in a stacked observation, oldest first."""
    return [
        {n: obs[n][..., i * f.shape[-1] : (i + 1) * f.shape[-1]] for n, f in frame.items()}
        for i in range(k)
    ]


def same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[n], b[n]) for n in a)


def test_sensor_space_stacks_frames_along_the_last_axis() -> None:
    shapes = {
        "camera": (120, 160, 3),
        "stereo": (120, 160, 6),
        "lidar": (192,),
        "sector_lidar": (24,),
        "discretized_sector_lidar": (192,),
    }
    for name in SENSOR_NAMES:
        one, three = sensor_space(name), sensor_space(name, stack_size=3)
        assert three.shape == shapes[name] and three.dtype == one.dtype
        assert np.array_equal(three.low[..., : one.shape[-1]], one.low)
        assert np.array_equal(three.high[..., -one.shape[-1] :], one.high)
    space = observation_space(("camera", "lidar"), stack_size=2)
    assert space["camera"].shape == (120, 160, 2) and space["lidar"].shape == (128,)
    for bad in (0, 9):
        with pytest.raises(ValueError, match="stack_size"):
            sensor_space("lidar", stack_size=bad)


def test_car_config_takes_stack_sizes_1_to_8() -> None:
    assert CarConfig(name="a").stack_size == 1 and CarConfig(name="a", stack_size=8).stack_size == 8
    for bad in (0, 9):
        with pytest.raises(ValidationError, match="stack_size"):
            CarConfig(name="a", stack_size=bad)


def test_stack_size_1_observes_single_frames() -> None:
    env = arena.parallel_env(sensors=("camera", "lidar"))
    obs, _ = env.reset()
    assert obs["car0"]["camera"].shape == (120, 160, 1) and obs["car0"]["lidar"].shape == (64,)
    assert env._stacks == {} and env._stack_sizes == {}  # nothing kept, nothing copied
    env.close()


@pytest.mark.parametrize("sensors", [("camera", "lidar"), ("stereo", "sector_lidar")])
def test_stack_holds_the_last_frames_in_order_through_a_respawn(sensors) -> None:
    """Side by side with the same seeded race unstacked: the stack is its last k frames;
    a race-mode penalty respawn does not refill it; a reset does."""
    k = 3
    config = arena.make_config(sensors=sensors, laps=1, time_limit_s=30.0, seed=5)
    flat, deep = RacingEnv(config), RacingEnv(stacked(config, k))
    assert deep.observation_space("car0") == observation_space(sensors, stack_size=k)
    first, _ = flat.reset()
    obs, _ = deep.reset()
    history = [first["car0"]]
    assert all(same(f, history[0]) for f in frames_of(obs["car0"], history[0], k))
    respawned_at = None
    for step in range(150):
        flat_obs, _, _, _, infos = flat.step({"car0": FULL_LOCK})
        obs, *_ = deep.step({"car0": FULL_LOCK})
        history.append(flat_obs["car0"])
        want = [history[max(0, len(history) - k + i)] for i in range(k)]
        assert all(
            same(got, w) for got, w in zip(frames_of(obs["car0"], want[0], k), want, strict=True)
        )
        assert deep.observation_space("car0").contains(obs["car0"])
        if respawned_at is None and infos["car0"]["off_track_count"]:
            respawned_at = step
        if respawned_at is not None and step >= respawned_at + 2:
            break
    assert respawned_at is not None, "the car never left the track"
    held = frames_of(obs["car0"], history[0], k)
    assert not same(held[0], held[-1])  # frames from before and after the respawn
    obs, _ = deep.reset()
    fresh = frames_of(obs["car0"], history[0], k)
    assert all(same(f, fresh[0]) for f in fresh)
    flat.close()
    deep.close()


def test_restart_car_refills_that_cars_stack_only() -> None:
    config = arena.make_config(race_type="head_to_model", num_cars=2, mode="training", seed=0)
    env = RacingEnv(stacked(config, 2, cars=("car0",)))
    _, infos = env.reset()
    driver = LaneFollowerPolicy(env.track, env.config.cars[1].action_space, speed=0.8)
    for _ in range(200):
        obs, _, _, _, step_infos = env.step(
            {"car0": FULL_LOCK, "car1": driver.act({}, params=infos["car1"]["params"])}
        )
        infos.update(step_infos)
        if "car0" not in env.agents:
            break
    assert "car0" not in env.agents
    assert obs["car1"]["lidar"].shape == (64,)  # car1 does not stack
    first, _ = env.restart_car("car0")
    assert first["lidar"].shape == (128,)
    assert np.array_equal(first["lidar"][:64], first["lidar"][64:])
    obs, *_ = env.step({"car0": 4, "car1": 4})
    assert np.array_equal(obs["car0"]["lidar"][:64], first["lidar"][64:])
    env.close()
